"""selfmodel from Python: robots as ROS ships them, their forward kinematics, learned
inverse kinematics (models `ik train` saves) and self-models (what a self-model run saves),
computed in Rust.

    import numpy as np, selfmodel
    robot = selfmodel.Robot.from_urdf("panda.urdf", tip="panda_hand")
    poses = robot.fk(np.zeros((1, robot.dof)))          # (1, 4, 4)
    silhouettes, depth = robot.render(np.zeros((1, robot.dof)))
    ik = selfmodel.IkSolver.load("runs/ik_models/panda")
    answer = ik.solve(targets)                           # targets (N, 7): x, y, z, qw, qx, qy, qz
    model = selfmodel.SelfModel.load("runs/neurokin")    # what a self-model run saved
    silhouettes, depth = model.predict(q)                # (N, H, W) float32; depth or None

Bad input (NaN, wrong shapes, another robot's model) raises ValueError with one line.
"""

from ._selfmodel import IkSolver, Robot, SelfModel

__all__ = ["IkSolver", "Robot", "SelfModel"]
