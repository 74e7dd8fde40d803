"""Collision spheres and the self-collision check, against Pinocchio and coal on the exact
collision meshes (PyPI `pin`, where it is installed)."""
import pathlib

import numpy as np
import pytest

import selfmodel

ROOT = pathlib.Path(__file__).resolve().parents[2]
PANDA = ROOT.parent / "shared" / "robots" / "franka_description" / "urdf" / "panda.urdf"
needs_panda = pytest.mark.skipif(not PANDA.is_file(), reason="the Panda's description (../shared/robots) is not here")

READY = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
FOLDED = [0.0, 1.7, 0.0, -3.0, 0.0, 0.5, 0.0]


@needs_panda
def test_spheres_pairs_collides_and_clearance_on_the_panda():
    robot = selfmodel.Robot.from_urdf(str(PANDA), tip="panda_hand")
    spheres = robot.collision_spheres
    assert {"panda_link0", "panda_link3", "panda_hand"} <= set(spheres)
    assert all(s.ndim == 2 and s.shape[1] == 4 and (s[:, 3] > 0).all() for s in spheres.values())
    pairs = robot.collision_pairs
    assert ("panda_link0", "panda_link1") not in pairs and ("panda_link1", "panda_link0") not in pairs
    assert any("panda_hand" in p for p in pairs)
    q = np.array([READY, FOLDED])
    assert robot.collides(q).tolist() == [False, True]
    c = robot.clearance(q)
    assert c[0] > 0.0 > c[1]
    # A margin larger than the ready pose's clearance makes it collide.
    assert robot.collides(q[:1], margin=c[0] + 0.01).tolist() == [True]
    with pytest.raises(ValueError, match="shape"):
        robot.collides(np.zeros((1, 3)))


def exact_collisions(pin, urdf, robot, q):
    """Whether each row of q collides on the exact meshes, checking our collision pairs."""
    package_root = urdf.parents[2]
    model, collision, _ = pin.buildModelsFromUrdf(str(urdf), package_dirs=[str(package_root)])
    checked = {tuple(sorted(p)) for p in robot.collision_pairs}
    objects = collision.geometryObjects
    link = [model.frames[g.parentFrame].name for g in objects]
    for i in range(len(objects)):
        for j in range(i + 1, len(objects)):
            if tuple(sorted((link[i], link[j]))) in checked:
                collision.addCollisionPair(pin.CollisionPair(i, j))
    data, cdata = model.createData(), pin.GeometryData(collision)
    out = []
    for row in q:
        full = pin.neutral(model)
        for name, value in zip(robot.joint_names, row):
            full[model.joints[model.getJointId(name)].idx_q] = value
        out.append(bool(pin.computeCollisions(model, data, collision, cdata, full, True)))
    return np.array(out)


@needs_panda
def test_the_exact_check_agrees_with_pinocchio_on_the_exact_meshes():
    pin = pytest.importorskip("pinocchio", reason="Pinocchio (PyPI pin) is not installed")
    robot = selfmodel.Robot.from_urdf(str(PANDA), tip="panda_hand")
    limits = robot.limits
    q = np.random.default_rng(5).uniform(limits[:, 0], limits[:, 1], size=(400, robot.dof))
    q = np.vstack([q, [READY, FOLDED]])
    ours = robot.collides(q)
    exact = exact_collisions(pin, PANDA, robot, q)
    # The known configurations, both ways.
    assert exact[-2:].tolist() == [False, True] and ours[-2:].tolist() == [False, True]
    # Decided on the same meshes (the spheres only its broad phase): the same answer for every
    # configuration, none missed and none called colliding that the meshes find free.
    differ = np.flatnonzero(exact != ours)
    print(f"{exact.mean():.1%} collide on the meshes, {ours.mean():.1%} by our check")
    assert differ.size == 0, f"ours {ours[differ][:3]}, the meshes {exact[differ][:3]} at {q[differ][:3]}"


PANDA_MODEL = ROOT / "runs" / "ik_models" / "panda"


@needs_panda
def test_ik_solve_with_a_scene_answers_collision_free(tmp_path):
    """A quick Panda model (trained here in seconds) answers targets drawn free of a table and
    a box; no answer marked exact collides, by the scene's check and by the robot's own."""
    import subprocess

    ik = ROOT / "target" / "release" / "ik"
    if not ik.is_file():
        pytest.skip("the ik binary is not built (cargo build --release)")
    model = tmp_path / "model"
    out = subprocess.run(
        [str(ik), "train", "--urdf", str(PANDA), "--tip", "panda_hand", "--preset", "quick", "--out", str(model)],
        capture_output=True, text=True,
    )
    assert out.returncode == 0, out.stderr
    scene = tmp_path / "scene.yml"
    scene.write_text(
        "cuboid:\n"
        "  table: {dims: [2, 2, 0.2], pose: [0, 0, -0.1, 1, 0, 0, 0]}\n"
        "  box: {dims: [0.1, 0.1, 0.3], pose: [0.45, 0.3, 0.15, 1, 0, 0, 0]}\n"
    )
    targets = tmp_path / "targets.csv"
    out = subprocess.run(
        [str(ik), "targets", "--model", str(model), "--scene", str(scene), "--n", "40", "--out", str(targets)],
        capture_output=True, text=True,
    )
    assert out.returncode == 0, out.stderr
    solver = selfmodel.IkSolver.load(str(model))
    rows = np.loadtxt(targets, delimiter=",", skiprows=1)[:, : len(solver.target_columns)]
    got = solver.solve(rows, k=2, scene=str(scene))
    assert got["collides"].shape == (40, 2)
    assert not (got["exact"] & got["collides"]).any()
    assert got["exact"].mean() >= 0.9, got["exact"].mean()
    robot = selfmodel.Robot.from_urdf(str(PANDA), tip="panda_hand")
    exact = got["joints"][got["exact"]]
    assert not robot.collides(exact, scene=str(scene), margin=0.005).any()
    assert (robot.clearance(exact, scene=str(scene)) >= 0.005).all()
    # Pinocchio and coal agree on the exact meshes at zero margin (scripts/collision_reference.py,
    # the scene's obstacles against every moving link, our pairs against each other).
    try:
        import pinocchio  # noqa: F401
        import yaml  # noqa: F401
    except ImportError:
        pass
    else:
        import json
        import sys
        joints = tmp_path / "answers.csv"
        np.savetxt(joints, exact, delimiter=",", header=",".join(robot.joint_names), comments="")
        pairs = tmp_path / "pairs.json"
        pairs.write_text(json.dumps([list(p) for p in robot.collision_pairs]))
        verdict = tmp_path / "exact.csv"
        out = subprocess.run(
            [sys.executable, str(ROOT / "scripts" / "collision_reference.py"), "--urdf", str(PANDA),
             "--joints", str(joints), "--checked", str(pairs), "--scene", str(scene), "--out", str(verdict)],
            capture_output=True, text=True,
        )
        assert out.returncode == 0, out.stderr
        collides = np.loadtxt(verdict, delimiter=",", skiprows=1, ndmin=1)
        assert collides.shape == (len(exact),) and not collides.any(), out.stdout
    # Without a scene nothing is checked, and there is no `collides`.
    assert "collides" not in solver.solve(rows[:3])
    with pytest.raises(ValueError, match="margin"):
        solver.solve(rows[:1], self_collision=True, margin=-1.0)
