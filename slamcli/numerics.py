"""Named tolerances instead of bare literals, each with the quantity it guards.

Values are those the code used as literals before; naming them changes no result.
"""

from __future__ import annotations

#: s. Rounding slack on time stamps of second scale: cutting a duration into whole steps
#: (``floor(duration/dt + TIME_EPS_S)``) and comparing a window end with the data's.
TIME_EPS_S = 1e-9
#: s. Two stamps closer than this are the same instant (an imported trajectory's pose is copied, not
#: interpolated; ``slamcli import trajectory --tol``).
STAMP_MATCH_TOL_S = 1e-6
#: m. Two points closer than this are one (polygon corners, duplicate waypoints); also the slack that keeps a
#: grid's end value when it is a whole number of spacings away.
POINT_EPS_M = 1e-9
#: Relative / absolute slack of a near-degenerate geometric test (a ray parallel to a wall: ``|den| ≤ this``;
#: a circle radius grown by ``1 + this`` so a tangent beam still hits).
GEOMETRY_EPS = 1e-12
#: Bound on the magnitude of any physical value a user or a file gives (m, s, m/s, rad, …): beyond it a value
#: is a typo or a hostile file, and squaring it (a distance, a cost) would overflow float64 (1e9² = 1e18 is
#: far from 1e308). Dataset arrays, imports and simulator parameters are checked against it.
MAX_INPUT_MAGNITUDE = 1e9
