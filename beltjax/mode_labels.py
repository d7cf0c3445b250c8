"""Labels of a drive's modes from their shapes: energy shares per span and body, half-waves,
repeated-frequency eigenspaces rotated so each mode is one span's, and the label strings."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from beltjax import ancf, drive, modal, span
from beltjax.scene import Scene

#: a mode below this frequency (Hz) is a rigid-body mode
RIGID_HZ = 1e-2
#: share of a class's energy above which a span/body is named in a label
NAME_SHARE = 0.25


def _ordinal(n):
    return modal.ordinal(int(n))


def _half_waves(w):
    """Half-waves of a displacement profile: interior nodes + 1.

    Real shapes: sign changes (ignoring values under 10 % of the maximum).  Complex
    modes of a moving belt carry a travelling phase along the span, so the real
    part's sign changes over-count; there a node is an interior local minimum of
    |w| under 35 % of its maximum (the standing-wave nodes).
    """
    w = np.asarray(w)
    a = np.abs(w)
    if a.size < 3 or np.max(a) == 0:
        return 1
    if np.max(np.abs(np.imag(w))) <= 1e-9 * np.max(a):
        r = np.real(w)
        s = np.sign(r[np.abs(r) > 0.1 * np.max(a)])
        return int(np.sum(s[1:] != s[:-1])) + 1
    inner = (a[1:-1] < a[:-2]) & (a[1:-1] <= a[2:]) & (a[1:-1] < 0.35 * np.max(a))
    return int(np.sum(inner)) + 1


def _fine_profile(u, Le, N, per_element: int = 16):
    """Displacement profile along a span from nodal (value, slope) pairs, by the cubic shape functions."""
    x = (np.arange(per_element) + 0.5) / per_element
    S = np.asarray(ancf.shape_functions(x, Le)).T  # (per_element, 4), the elements' own
    nodes = u.reshape(N + 1, 2, -1)
    elem = np.concatenate([nodes[:-1], nodes[1:]], axis=1)  # (N, 4, modes)
    return np.einsum("pk,ekm->epm", S, elem).reshape(N * per_element, -1)


def energy_shares(shapes, qi, scene: Scene, inst, J=None):
    """Kinetic-energy shares of each mode: dict name -> (n_modes,) array summing to 1.

    Names: "<span> transverse", "<span> longitudinal" per span, and each body's
    name (pulleys, "tensioner" idler, "tensioner arm").  Also returns the
    per-span transverse and longitudinal profiles, (n_modes, n_spans, n_points).
    """
    if J is None:
        J = jax.jacfwd(lambda x: drive.full_coordinates(x, scene, inst))(jnp.asarray(qi))
    V = np.asarray(J) @ np.asarray(shapes)  # full-coordinate shapes (complex)
    return full_energy_shares(V, scene, label_arrays(scene, inst))


def label_arrays(scene: Scene, inst) -> dict:
    """What labels need of an equilibrium besides the shapes (pure JAX): element lengths Le (m)
    per span, span tangents, and the bodies' mass diagonal body_mass (kg, kg m^2)."""
    return dict(Le=drive.element_length(scene, inst), tangent=inst.span_tangent,
                body_mass=drive.body_masses(scene, inst))


def full_energy_shares(V, scene: Scene, arrays: dict):
    """:func:`energy_shares` of full-coordinate shapes V (n_full, n_modes) with :func:`label_arrays`."""
    V = np.asarray(V)
    n = len(scene.route.order)
    N = drive.span_elements(scene)
    ns = 4 * (N + 1)
    Le = np.asarray(arrays["Le"])
    t = np.asarray(arrays["tangent"])
    nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
    shares, trans, longi = {}, [], []
    names = drive.span_names(scene)
    for s in range(n):
        Ms = np.asarray(span.span_component_mass(float(drive.spans_of(scene).mass_per_length(scene.belt.rhoA)),
                                                   float(Le[s]), N))
        blk = V[s * ns : (s + 1) * ns].reshape(N + 1, 2, 2, -1)  # node, (pos, slope), (x, y), mode
        ul = np.einsum("nkdm,d->nkm", blk, t[s]).reshape(2 * (N + 1), -1)
        ut = np.einsum("nkdm,d->nkm", blk, nrm[s]).reshape(2 * (N + 1), -1)
        shares[f"{names[s]} longitudinal"] = np.real(np.einsum("im,ij,jm->m", ul.conj(), Ms, ul))
        shares[f"{names[s]} transverse"] = np.real(np.einsum("im,ij,jm->m", ut.conj(), Ms, ut))
        trans.append(_fine_profile(ut, Le[s], N))
        longi.append(_fine_profile(ul, Le[s], N))
    B = V[n * ns :].reshape(-1, 3, V.shape[1])
    mass = np.asarray(arrays["body_mass"]).reshape(-1, 3)
    for b, name in enumerate(drive.body_names(scene)):
        shares[name] = np.real(np.einsum("km,k,km->m", B[b].conj(), mass[b], B[b]))
    total = sum(shares.values())
    total = np.where(total > 0, total, 1.0)
    shares = {k: v / total for k, v in shares.items()}
    return shares, np.stack(trans).transpose(2, 0, 1), np.stack(longi).transpose(2, 0, 1)


#: relative frequency difference below which modes form one eigenspace (a repeated pair)
REPEATED_RTOL = 1e-7


def localise_repeated(freqs, shapes, M, J, scene: Scene, inst) -> np.ndarray:
    """Real shapes (n, n_modes) with the basis of every repeated eigenspace chosen by the spans.

    Any basis of a repeated eigenspace is a valid set of modes, and eigh returns an arbitrary
    one: two equal spans' transverse modes come out as mixtures of both ("a + b").  Within
    each cluster of frequencies equal to ``REPEATED_RTOL`` (M-orthonormal columns), the
    basis is rotated to the eigenvectors of the span-energy form that separates the cluster
    most (the transverse or longitudinal kinetic energy of one span, or one body's), so each
    mode is as much one span's as the eigenspace allows.  Frequencies are unchanged; numpy.
    """
    V = np.array(np.real(shapes), dtype=float)
    f = np.asarray(freqs)
    M = np.asarray(M)
    arrays = label_arrays(scene, inst)
    Jn = np.asarray(J)
    i = 0
    while i < len(f):
        j = i + 1
        while j < len(f) and f[i] >= RIGID_HZ and abs(f[j] - f[i]) <= REPEATED_RTOL * f[i]:
            j += 1
        if j - i >= 2:
            C = V[:, i:j]
            k = j - i
            pairs = [(a, b) for a in range(k) for b in range(a, k)]
            combos = np.stack([C[:, a] + C[:, b] if a != b else C[:, a] for a, b in pairs], axis=1)
            shares, _, _ = full_energy_shares(Jn @ combos, scene, arrays)
            total = np.einsum("im,ij,jm->m", combos, M, combos)
            best, R = -1.0, None
            for share in shares.values():
                E = share * total  # the energy of that span or body in each combination
                A = np.zeros((k, k))
                for (a, b), e in zip(pairs, E):
                    A[a, b] = e
                for a, b in pairs:
                    if a != b:
                        A[a, b] = A[b, a] = 0.5 * (A[a, b] - A[a, a] - A[b, b])
                w, U = np.linalg.eigh(0.5 * (A + A.T))
                if w[-1] - w[0] > best:
                    best, R = w[-1] - w[0], U
            V[:, i:j] = C @ R
        i = j
    return V


def label_modes(freqs, shapes, qi, scene: Scene, inst, J=None):
    """Labels ("1st transverse crank-alternator", "2nd rotational (alternator, crank)", "rigid body").

    Returns (labels, shares dict).  Transverse and longitudinal orders count the
    half-waves of the dominant span's profile; rotational orders count modes.
    """
    shares, trans, longi = energy_shares(shapes, qi, scene, inst, J)
    return _labels(freqs, shares, trans, longi, scene), shares


def label_full(freqs, V, scene: Scene, arrays: dict):
    """:func:`label_modes` of full-coordinate shapes V (n_full, n_modes) with :func:`label_arrays`
    (e.g. from :func:`tracking_shapes`, computed under jit): (labels, shares dict)."""
    shares, trans, longi = full_energy_shares(V, scene, arrays)
    return _labels(freqs, shares, trans, longi, scene), shares


def _labels(freqs, shares, trans, longi, scene: Scene) -> list[str]:
    names = drive.span_names(scene)
    bodies = drive.body_names(scene)
    labels, n_rot = [], 0
    for m, f in enumerate(np.asarray(freqs)):
        if f < RIGID_HZ:
            labels.append("rigid body")
            continue
        tr = np.array([shares[f"{s} transverse"][m] for s in names])
        lo = np.array([shares[f"{s} longitudinal"][m] for s in names])
        ro = np.array([shares[b][m] for b in bodies])
        kind = int(np.argmax([tr.sum(), lo.sum(), ro.sum()]))
        if kind == 2:
            n_rot += 1
            order = np.argsort(-ro)
            who = [bodies[i] for i in order if ro[i] >= NAME_SHARE * ro.sum()]
            labels.append(f"{_ordinal(n_rot)} rotational ({', '.join(who)})")
            continue
        part = tr if kind == 0 else lo
        prof = trans if kind == 0 else longi
        order = np.argsort(-part)
        who = [names[i] for i in order if part[i] >= NAME_SHARE * part.sum()]
        k = _half_waves(prof[m, order[0]])
        word = "transverse" if kind == 0 else "longitudinal"
        labels.append(f"{_ordinal(k)} {word} {' + '.join(who)}")
    return labels
