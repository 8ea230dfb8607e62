"""Standard manoeuvres: zig-zag and turning-circle tests on any vehicle model (no Gymnasium).

A model qualifies if it has a rudder input (``delta`` by default) and a heading state (``psi``);
the turning circle also needs the body velocities ``u``, ``v`` and the yaw rate ``r``. A ``speed``
argument needs the model to offer ``trim_point(speed) -> (x, u)`` (straight running at ``speed``).
Everything is in SI units and radians; the results also give the angles in degrees.

Zig-zag (ITTC 7.5-04-02-01, "Z-test" A/B): from steady straight running the rudder goes to +A
(starboard) at t = 0 (first execute). When the heading change from the initial heading reaches +B
the rudder goes to -A (second execute), when it reaches -B back to +A, and so on. The rudder moves
instantaneously by default (the ITTC test asks for the quickest rudder); a rate limit is optional.

Definitions used for the zig-zag metrics (times from the first execute, t = 0):

* initial turning time: time of the second execute (heading change first reaches +B);
* first (second) overshoot angle: how far the heading change goes past +B (-B) after the second
  (third) execute, i.e. ``max(psi - psi_0) - B`` (``-min(psi - psi_0) - B``);
* first peak heading ("maximum heading" in docs/models.md 5.3): ``B + first overshoot``, reached
  at the first peak time; time to check yaw = first peak time - initial turning time;
* period: time of one full cycle, from the second to the fourth execute.

:func:`read_zigzag` reads the same criteria (and A, B, the first direction, the rudder rate) off a
measured heading and rudder history, a record or a prediction alike; :func:`read_turn` a turn's
steady rudder and turning rate.

Turning circle: the rudder is held at ``delta`` from steady straight running. Steady values are
those at the end of the run: yaw rate r, drift angle ``beta = atan2(-v, u)`` (positive when the
velocity points out of a starboard turn, the beta of docs/models.md 5.2), speed
``U = hypot(u, v)`` and radius ``R = U/|r|``. Advance and transfer are read at a heading change
of 90 deg, the tactical diameter at 180 deg (transfer normal to the approach course).

Both are integrated by classical RK4 (:mod:`~marine_envs.manoeuvres.simulation`) with the inputs
held over each step (the rudder command is updated at the start of a step), as in the checks of
docs/models.md 5.3 (dt = 0.05 s). The rudder law lives in :mod:`~marine_envs.manoeuvres.rudder`,
the reading of a history in :mod:`~marine_envs.manoeuvres.reading`.
"""

from .reading import TurnCriteria, ZigzagCriteria, ZigzagMetrics, read_turn, read_zigzag
from .rudder import HEADING_NAMES, RUDDER_NAMES, ZigzagRudder, wrap_angle
from .simulation import TurningResult, ZigzagResult, turning_circle, zigzag

__all__ = ["HEADING_NAMES", "RUDDER_NAMES", "TurnCriteria", "TurningResult", "ZigzagCriteria",
           "ZigzagMetrics", "ZigzagResult", "ZigzagRudder", "read_turn", "read_zigzag",
           "turning_circle", "wrap_angle", "zigzag"]
