"""Motion and observation models shared by the simulator and every solver.

Frames and conventions (used everywhere in slamcli):

* world frame: x east, y north, metres; heading ``theta`` counter-clockwise from the x axis, radians,
  always wrapped to ``[-pi, pi)`` by :func:`slamcli.models.angles.wrap_angle`.
* a pose is ``xyt = [x, y, theta]``; arrays of poses are ``poses_xyt (T+1, 3)``.
* a range-bearing measurement is ``z = [range, bearing]``, bearing measured from the robot's heading,
  counter-clockwise positive, wrapped to ``[-pi, pi)``. (Paper 000 measures bearing from the robot's
  right side, ``b_paper = b + pi/2``; see :func:`slamcli.models.observation.to_paper_bearing`.)
* a control is ``u = [v, omega]`` (m/s, rad/s) applied for ``dt`` seconds.
"""
