"""beltjax.identification: belt and tensioner parameters from bench data.

``beltjax fit DATA.toml`` reads a dataset (see ``../shared/DESIGN.md``) whose sections are
fitted by one module each: ``[tensile]`` (:mod:`identification.tensile`), ``[torque_angle]``
(:mod:`identification.torque_angle`), ``[impulse]`` (:mod:`identification.damping`) and
``[modal]`` (:mod:`identification.modal_fit`).
"""
