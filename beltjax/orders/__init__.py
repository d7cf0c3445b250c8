"""Responses over engine speed (``beltjax orders``): the periodic steady state of a drive at each
speed, by shooting or a settling transient, batched and differentiable (:mod:`beltjax.orders.steady`,
:mod:`beltjax.orders.shooting`, :mod:`beltjax.orders.run`)."""

from beltjax.orders.run import (FLAGS_KEEPING_NUMBERS, MAX_SPEEDS, SETTLE_TOL, STATUS, OrdersError, OrdersResult, check, fallback_device,
                                fallback_passes, needs_rerun, over_speed, response_over_speed)
from beltjax.orders.shooting import periodic_orbit
from beltjax.orders.steady import CHANNELS, METHODS, Settings, cycle_revolutions, for_scene, steady_case

__all__ = ["CHANNELS", "FLAGS_KEEPING_NUMBERS", "MAX_SPEEDS", "METHODS", "SETTLE_TOL", "STATUS", "OrdersError", "OrdersResult", "Settings",
           "check", "cycle_revolutions", "fallback_device", "fallback_passes", "for_scene", "needs_rerun", "over_speed",
           "periodic_orbit", "response_over_speed", "steady_case"]
