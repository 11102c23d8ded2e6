"""UR5e motion planning for the MESP cell (paper sections 3.1 and 5.2).

Modules: ``cell`` (cell description TOML), ``kinematics`` (DH FK, Jacobian, closed-form IK),
``collision`` (capsule/box clearances), ``orientation`` (nozzle axis, spin and alpha tilt),
``placement`` (model position in the tank), ``timing`` (DLS joint rates, time law),
``trajectory`` (the trajectory.npz stage), ``plan`` (the pipeline) and ``plots``.
"""
