"""The Python package against the command line on the same inputs, and bad input.

Needs the `ik` and `neurokin` binaries (`cargo build --release --bin ik --bin neurokin`, which
CI's test command builds) and a robot description: the test arm written here.
"""

import csv
import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

import selfmodel

ROOT = pathlib.Path(__file__).resolve().parents[2]
IK = ROOT / "target" / "release" / "ik"
NEUROKIN = ROOT / "target" / "release" / "neurokin"

ARM = """<?xml version="1.0"?>
<robot name="test_arm">
  <link name="base"/>
  {links}
</robot>
"""


def write_arm(folder: pathlib.Path, joints: int = 6) -> pathlib.Path:
    """A serial arm of `joints` revolute joints (alternating axes) with a hand."""
    parts = []
    for j in range(joints):
        parent = "base" if j == 0 else f"l{j}"
        axis = "0 0 1" if j % 2 == 0 else "0 1 0"
        parts.append(
            f'<link name="l{j + 1}"/><joint name="j{j + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{j + 1}"/><origin xyz="0 0 0.1"/><axis xyz="{axis}"/>'
            f'<limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>'
        )
    parts.append(
        f'<link name="hand"/><joint name="hand_joint" type="fixed"><parent link="l{joints}"/>'
        f'<child link="hand"/><origin xyz="0 0 0.08"/></joint>'
    )
    path = folder / "arm.urdf"
    path.write_text(ARM.format(links="\n  ".join(parts)))
    return path


def write_visible_arm(folder: pathlib.Path) -> pathlib.Path:
    """The test arm with a box on its first link and a cylinder on its third (to render)."""
    urdf = folder / "visible.urdf"
    urdf.write_text(
        write_arm(folder).read_text().replace(
            '<link name="l1"/>',
            '<link name="l1"><visual><geometry><box size="0.05 0.05 0.2"/></geometry></visual></link>',
        ).replace(
            '<link name="l3"/>',
            '<link name="l3"><visual><geometry><cylinder radius="0.03" length="0.2"/></geometry></visual></link>',
        )
    )
    return urdf


def run(*args: str) -> str:
    out = subprocess.run([str(IK), *args], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A quick model of the test arm, 200 random reachable targets and the CLI's answers."""
    folder = tmp_path_factory.mktemp("ik")
    urdf = write_arm(folder)
    model = folder / "model"
    run("train", "--urdf", str(urdf), "--tip", "hand", "--preset", "quick", "--out", str(model))
    targets = folder / "targets.csv"
    run("targets", "--model", str(model), "--n", "200", "--out", str(targets))
    answers = folder / "answers.csv"
    run("solve", "--model", str(model), "--targets", str(targets), "--out", str(answers))
    return urdf, model, targets, answers


def read_csv(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], np.array([[float(x) if x not in ("true", "false") else x == "true" for x in r] for r in rows[1:]], dtype=object)


def test_fk_gives_the_poses_the_command_line_wrote(trained):
    urdf, _, targets, _ = trained
    robot = selfmodel.Robot.from_urdf(str(urdf), tip="hand", geometry="none")
    assert robot.joint_names == [f"j{i}" for i in range(1, 7)]
    assert robot.limits.shape == (6, 2)
    header, rows = read_csv(targets)
    q = rows[:, 7:].astype(float)
    poses = robot.fk(q)
    assert poses.shape == (200, 4, 4)
    np.testing.assert_allclose(poses[:, :3, 3], rows[:, :3].astype(float), atol=1e-9)
    # The rotation's quaternion (w >= 0 up to sign) matches the columns qw, qx, qy, qz.
    r = poses[:, :3, :3]
    w = np.sqrt(np.maximum(0, 1 + r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2])) / 2
    qw = rows[:, 3].astype(float)
    np.testing.assert_allclose(np.abs(w), np.abs(qw), atol=1e-6)
    jac = robot.jacobian(q[:3])
    assert jac.shape == (3, 6, 6)


def test_solve_answers_as_the_command_line_does(trained):
    urdf, model, targets, answers = trained
    ik = selfmodel.IkSolver.load(str(model))
    assert ik.target_columns == ["x", "y", "z", "qw", "qx", "qy", "qz"]
    _, rows = read_csv(targets)
    out = ik.solve(rows[:, :7].astype(float))
    assert out["joints"].shape == (200, 1, 6)
    header, cli = read_csv(answers)
    joints = cli[:, 2:8].astype(float)
    np.testing.assert_allclose(out["joints"][:, 0, :], joints, atol=1e-9)
    np.testing.assert_array_equal(out["exact"][:, 0], cli[:, -1].astype(bool))
    assert out["exact"].mean() >= 0.95
    one = ik.solve_one(list(rows[0, :7].astype(float)))
    np.testing.assert_allclose(one, joints[0], atol=1e-9)
    # Exact answers are converged to the tolerance (1e-4 mm and 1e-4 degrees by default; on
    # this arm a target near a singularity may keep a stalled answer inside the threshold, so
    # the 98th percentile), and a looser tolerance stops them sooner, still exact.
    exact = out["exact"][:, 0]
    assert np.percentile(out["pos_err_mm"][exact, 0], 98) <= 1e-4
    assert np.percentile(out["rot_err_deg"][exact, 0], 98) <= 1e-4
    assert out["pos_err_mm"][exact, 0].max() <= 1.0
    loose = ik.solve(rows[:, :7].astype(float), tolerance=(0.5, 0.2))
    assert loose["exact"].mean() >= 0.95
    assert loose["pos_err_mm"][loose["exact"]].max() <= 0.5
    assert np.median(loose["pos_err_mm"]) > np.median(out["pos_err_mm"])


def test_bad_input_raises_value_error_in_one_line(trained, tmp_path):
    urdf, model, _, _ = trained
    robot = selfmodel.Robot.from_urdf(str(urdf), tip="hand", geometry="none")
    ik = selfmodel.IkSolver.load(str(model))
    fifo = tmp_path / "robot.urdf"
    os.mkfifo(fifo)
    cases = [
        lambda: robot.fk(np.zeros((2, 5))),
        lambda: robot.fk(np.full((1, 6), np.nan)),
        lambda: robot.fk(np.zeros((1, 6)), link="nope"),
        lambda: ik.solve(np.zeros((3, 6))),
        lambda: ik.solve(np.array([[0.1, 0.2, 0.3, 2.0, 0, 0, 0]])),
        lambda: ik.solve(np.array([[1e39, 0.2, 0.3, 1.0, 0, 0, 0]])),
        lambda: ik.solve(np.zeros((1, 7)), k=0),
        lambda: ik.solve(np.zeros((1, 7)), tolerance=(float("nan"), 1e-4)),
        lambda: ik.solve(np.zeros((1, 7)), tolerance=(1e-4, -1.0)),
        lambda: ik.solve(np.zeros((1, 7)), tolerance=(5.0, 1e-4)),
        lambda: ik.solve_one([0.1, 0.2]),
        lambda: selfmodel.Robot.from_urdf(str(tmp_path / "missing.urdf")),
        lambda: selfmodel.Robot.from_urdf(str(urdf), geometry="shiny"),
        lambda: selfmodel.IkSolver.load(str(tmp_path)),
        # 10^9 rows as a broadcast view (no memory in numpy): refused before any copy.
        lambda: robot.fk(np.broadcast_to(np.zeros(6), (10**9, 6))),
        lambda: ik.solve(np.broadcast_to(np.zeros(7), (10**9, 7))),
        # A robot with no joint to move: its tip is the root.
        lambda: selfmodel.Robot.from_urdf(str(urdf), tip="base"),
        # A FIFO where a file is read would block forever.
        lambda: selfmodel.Robot.from_urdf(str(fifo)),
    ]
    for case in cases:
        with pytest.raises(ValueError) as e:
            case()
        assert "\n" not in str(e.value), str(e.value)
    with pytest.raises(TypeError):
        robot.fk("not an array")
    # A panic (a bug) reaches Python as a RuntimeError of one line, not a PanicException.
    with pytest.raises(RuntimeError, match="a bug") as e:
        selfmodel.Robot._panic_for_test()
    assert "\n" not in str(e.value)
    with pytest.raises(TypeError, match="numbers"):
        robot.fk(np.zeros((1, 6), dtype=complex))
    for bad in [lambda: ik.solve(np.zeros((1, 7)), k=-1), lambda: robot.render(np.zeros((1, 6)), size=-5)]:
        with pytest.raises(ValueError, match="must be 1 to"):
            bad()
    with pytest.raises(ValueError, match="`group`"):
        selfmodel.Robot.from_urdf(str(urdf), srdf=str(urdf))
    # What numpy can cast safely is accepted: big-endian, float32, integers, any strides.
    q = np.linspace(-1, 1, 12).reshape(2, 6)
    want = robot.fk(q)
    for same in [q.astype(">f8"), np.asfortranarray(q), np.repeat(q, 2, axis=1)[:, ::2]]:
        assert np.array_equal(robot.fk(same), want)
    assert np.allclose(robot.fk(q.astype(np.float32)), want, atol=1e-6)
    assert robot.fk(np.zeros((1, 6), dtype=np.int64)).shape == (1, 4, 4)
    assert selfmodel.Robot.from_urdf(str(urdf), joints="all", geometry="none").dof == 6
    # A model of another robot: the description it names now has a joint renamed.
    text = urdf.read_text()
    urdf.write_text(text.replace('"j2"', '"elbow"'))
    try:
        with pytest.raises(ValueError, match="j2"):
            selfmodel.IkSolver.load(str(model))
    finally:
        urdf.write_text(text)


def interrupted(call, after=0.5):
    """Calls `call` over and over until a Ctrl-C raised `after` seconds in stops it (so the
    signal never lands outside the call's loop, however fast this machine runs it); returns the
    seconds from the Ctrl-C to the KeyboardInterrupt, and how many calls ended before it."""
    import signal
    import threading
    import time

    raised = []

    def ctrl_c():
        raised.append(time.monotonic())
        signal.raise_signal(signal.SIGINT)

    # Python's own Ctrl-C handler, whatever this process inherited: a shell that starts a
    # command in the background (`cmd &`) starts it with SIGINT ignored, and the loop below
    # would then never end.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    threading.Timer(after, ctrl_c).start()
    completed = 0
    try:
        while True:
            call()
            completed += 1
    except KeyboardInterrupt:
        return time.monotonic() - raised[0], completed
    finally:
        signal.signal(signal.SIGINT, previous)


def test_ctrl_c_interrupts_every_long_call_within_a_second(trained, neurokin_run, tmp_path):
    """KeyboardInterrupt reaches Python from inside every long call (between blocks of rows,
    images or targets), within a second of Ctrl-C."""
    _, model, _, _ = trained
    robot = selfmodel.Robot.from_urdf(str(write_visible_arm(tmp_path)), tip="hand")
    ik = selfmodel.IkSolver.load(str(model))
    nk = selfmodel.SelfModel.load(neurokin_run[0])
    calls = {
        "fk": lambda: robot.fk(np.zeros((3_000_000, 6))),
        "jacobian": lambda: robot.jacobian(np.zeros((3_000_000, 6))),
        "render": lambda: robot.render(np.zeros((10_000, 6)), size=100),
        "predict": lambda: nk.predict(np.zeros((100_000, nk.inputs))),
        "solve": lambda: ik.solve(np.tile(np.array([[0.1, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0]]), (200_000, 1))),
    }
    slow = []
    for name, call in calls.items():
        waited, completed = interrupted(call)
        print(f"{name}: KeyboardInterrupt {waited:.3f} s after Ctrl-C, {completed} calls completed before it")
        if waited > 1.0:
            slow.append(f"{name}: {waited:.2f} s after Ctrl-C")
    assert not slow, slow

def test_render_draws_what_the_command_line_renders(tmp_path):
    """Silhouettes and depth of poses from Python equal `dataset --angles` on the same poses
    (the same framing over them, the same ray caster)."""
    urdf = write_visible_arm(tmp_path)
    robot = selfmodel.Robot.from_urdf(str(urdf), tip="hand")
    rng = np.random.default_rng(0)
    lo, hi = robot.limits[:, 0], robot.limits[:, 1]
    q = lo + (hi - lo) * rng.random((5, robot.dof))
    silhouettes, depth = robot.render(q)
    assert silhouettes.shape == (5, 100, 100) and silhouettes.dtype == np.uint8
    assert depth.shape == (5, 100, 100) and depth.dtype == np.float32
    assert (silhouettes > 0).any() and ((silhouettes > 0) == (depth > 0)).all()
    angles = tmp_path / "angles.csv"
    np.savetxt(angles, np.degrees(q), delimiter=",", fmt="%.17g")
    npz = tmp_path / "d.npz"
    out = subprocess.run(
        [str(ROOT / "target" / "release" / "dataset"), "--urdf", str(urdf), "--tip", "hand",
         "--angles", str(angles), "--out", str(npz)],
        capture_output=True, text=True,
    )
    assert out.returncode == 0, out.stderr
    data = np.load(npz)
    np.testing.assert_array_equal(data["images"], silhouettes)
    np.testing.assert_allclose(data["depth"], depth, atol=1e-5)
    assert list(data["joint_names"]) == robot.joint_names
    with pytest.raises(ValueError):
        robot.render(q, size=0)


@pytest.fixture(scope="module")
def neurokin_run(tmp_path_factory):
    """NeuroKin's quick preset trained by the command line: its folder and results row."""
    folder = tmp_path_factory.mktemp("neurokin") / "run"
    out = subprocess.run(
        [str(NEUROKIN), "--preset", "quick", "--out", str(folder)], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    with open(folder / "results.csv", newline="") as f:
        return folder, next(csv.DictReader(f))


def test_a_saved_self_model_predicts_what_its_run_evaluated(neurokin_run):
    folder, row = neurokin_run
    model = selfmodel.SelfModel.load(folder)
    assert model.name == "NeuroKin"
    assert abs(model.info["psnr_db_test"] - float(row["psnr_db_test"])) < 1e-9
    # The probe: test poses and what the command line's evaluation predicted for them.
    probe = np.load(folder / "model" / "probe.npz")
    # The probe keeps the model's inputs in the dataset's units (degrees); predict takes
    # radians, as every other call does.
    radians = np.radians(probe["angles"].astype(np.float64))
    silhouettes, depth = model.predict(radians)
    assert depth is None
    assert silhouettes.shape == probe["silhouettes"].shape and silhouettes.dtype == np.float32
    assert np.abs(silhouettes - probe["silhouettes"]).max() < 1e-5
    # Other poses give other images, within [0, 1].
    moved = model.predict(radians + np.radians(20.0))[0]
    assert 0.0 <= moved.min() and moved.max() <= 1.0
    assert np.abs(moved - silhouettes).max() > 0.05
    # Degrees given where radians are taken are other poses, not the probe's.
    assert np.abs(model.predict(np.degrees(radians))[0] - silhouettes).max() > 0.05


def test_a_self_model_refuses_bad_input_and_damaged_weights(neurokin_run, tmp_path):
    import shutil

    folder, _ = neurokin_run
    model = selfmodel.SelfModel.load(folder)
    bad = [
        (np.zeros((2, model.inputs + 1)), "expected an array of shape"),
        (np.full((1, model.inputs), np.nan), "not a finite number"),
    ]
    for q, says in bad:
        with pytest.raises(ValueError, match=says) as e:
            model.predict(q)
        assert "\n" not in str(e.value)
    with pytest.raises(TypeError):
        model.predict(np.zeros((1, model.inputs), dtype=np.complex128))
    with pytest.raises(ValueError, match="no saved self-model here"):
        selfmodel.SelfModel.load(tmp_path)
    copy = tmp_path / "copy"
    shutil.copytree(folder / "model", copy)
    weights = bytearray((copy / "model.bpk").read_bytes())
    weights[len(weights) // 2] ^= 0xFF
    (copy / "model.bpk").write_bytes(bytes(weights))
    with pytest.raises(ValueError, match="damaged or replaced"):
        selfmodel.SelfModel.load(copy)


PANDA = ROOT.parent / "shared" / "robots" / "franka_description" / "urdf" / "panda.urdf"


@pytest.mark.skipif(not PANDA.is_file(), reason="the Panda's description (../shared/robots) is not here")
def test_fk_matches_pinocchio_on_the_panda():
    pin = pytest.importorskip("pinocchio", reason="Pinocchio (PyPI pin) is not installed")
    robot = selfmodel.Robot.from_urdf(str(PANDA), tip="panda_hand")
    model = pin.buildModelFromUrdf(str(PANDA))
    data = model.createData()
    limits = robot.limits
    q = np.random.default_rng(3).uniform(limits[:, 0], limits[:, 1], size=(200, robot.dof))
    ours = robot.fk(q)
    hand = model.getFrameId("panda_hand")
    worst = 0.0
    for qi, pose in zip(q, ours):
        full = pin.neutral(model)
        for name, value in zip(robot.joint_names, qi):
            full[model.joints[model.getJointId(name)].idx_q] = value
        pin.framesForwardKinematics(model, data, full)
        worst = max(worst, np.abs(data.oMf[hand].homogeneous - pose).max())
    assert worst < 1e-9, f"largest difference from Pinocchio: {worst:.2e}"


@pytest.mark.skipif(not PANDA.is_file(), reason="the Panda's description (../shared/robots) is not here")
def test_the_example_runs(tmp_path):
    pytest.importorskip("matplotlib", reason="the example draws with matplotlib")
    import sys

    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "python" / "panda_ik.py"), "--out", str(tmp_path / "ik.png")],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
    exact = float(out.stdout.split("% exact")[0].split()[-1])
    assert exact >= 95.0, out.stdout
    assert (tmp_path / "ik.png").stat().st_size > 10_000


def test_a_group_of_the_srdf_beside_the_urdf(tmp_path):
    urdf = write_arm(tmp_path, 6)
    (tmp_path / "arm.srdf").write_text(
        '<robot name="test_arm"><group name="wrist"><joint name="j5"/><joint name="j6"/></group>'
        '<group name="upper"><chain base_link="base" tip_link="l3"/></group></robot>'
    )
    assert selfmodel.Robot.from_urdf(str(urdf), group="wrist").joint_names == ["j5", "j6"]
    upper = selfmodel.Robot.from_urdf(str(urdf), group="upper")
    assert upper.joint_names == ["j1", "j2", "j3"]
    with pytest.raises(ValueError, match="is not a group"):
        selfmodel.Robot.from_urdf(str(urdf), group="legs")


def test_the_argument_converters_take_or_refuse_any_array(trained):
    """Bounded fuzzing of the argument converters: arrays of every numpy dtype, byte order,
    shape and stride (seeded), values NaN, huge or ordinary, and objects that are not arrays,
    given to fk, jacobian and solve: each returns a correct-shaped answer or raises ValueError
    or TypeError in one line; the interpreter never dies."""
    urdf, model, _, _ = trained
    robot = selfmodel.Robot.from_urdf(str(urdf), tip="hand", geometry="none")
    ik = selfmodel.IkSolver.load(str(model))
    rng = np.random.default_rng(5)
    dtypes = [np.float64, np.float32, np.float16, np.int8, np.int64, np.uint16, np.bool_, np.complex64, ">f8", "<f4", object, "U3"]
    values = [0.3, np.nan, np.inf, -1e300, 1e39, 0.0]
    calls = [
        (robot.fk, 6, lambda out, n: out.shape == (n, 4, 4)),
        (robot.jacobian, 6, lambda out, n: out.shape[0] == n),
        (lambda a: ik.solve(a)["joints"], 7, lambda out, n: out.shape == (n, 1, 6)),
    ]
    accepted = refused = 0
    for _ in range(300):
        call, width, ok = calls[rng.integers(len(calls))]
        n = int(rng.integers(0, 4))
        cols = width if rng.random() < 0.7 else int(rng.integers(0, 9))
        shape = [(n, cols), (cols,), (n, cols, 1), (), (n * cols,)][rng.integers(5) if rng.random() < 0.3 else 0]
        dtype = dtypes[rng.integers(len(dtypes))]
        base = np.full(shape, values[rng.integers(len(values))] if rng.random() < 0.5 else 0.2)
        if width == 7 and base.ndim == 2 and base.shape[1] == 7:
            base[:, 3] = 1.0  # a unit quaternion where the values allow one
        try:
            with np.errstate(invalid="ignore", over="ignore"):
                a = base.astype(dtype)
        except (ValueError, OverflowError):
            continue
        if a.ndim == 2 and rng.random() < 0.3:
            a = np.asfortranarray(a)
        if a.ndim == 2 and a.shape[0] > 1 and rng.random() < 0.3:
            a = a[::-1]
        arg = a if rng.random() < 0.9 else [list(map(str, a.ravel()))]
        try:
            out = call(arg)
        except (ValueError, TypeError) as e:
            assert "\n" not in str(e), str(e)
            refused += 1
            continue
        if a.ndim == 2:
            assert ok(np.asarray(out), a.shape[0]), (a.dtype, a.shape)
        accepted += 1
    assert accepted > 10 and refused > 10, (accepted, refused)


def _edit_json(path, change):
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def _nan_weights_with_their_hash(folder):
    """A NaN written into the weights, and model.json's hash recomputed to match (FNV-1a)."""
    import struct

    weights = bytearray((folder / "model.bpk").read_bytes())
    middle = len(weights) // 2 & ~3
    weights[middle : middle + 4] = struct.pack("<f", float("nan"))
    (folder / "model.bpk").write_bytes(bytes(weights))
    h = 0xCBF29CE484222325
    for b in weights:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    _edit_json(folder / "model.json", lambda j: j.update(weights_fnv=f"{h:016x}"))


def _replace_by_fifo(path):
    path.unlink()
    os.mkfifo(path)


def test_round_four_cases_are_refused_in_one_line(trained, neurokin_run, tmp_path):
    """Issue 59's Python cases, each a row: what a user or an attacker gives, and the words of
    the one-line ValueError expected (the interpreter never dies, nothing hangs)."""
    import shutil

    urdf, model, _, _ = trained
    robot = selfmodel.Robot.from_urdf(str(urdf), tip="hand", geometry="none")
    folder, _ = neurokin_run
    nk = selfmodel.SelfModel.load(folder)
    n = nk.inputs

    def write(name, text):
        (tmp_path / name).write_text(text)
        return str(tmp_path / name)

    deep_srdf = write("deep.srdf", '<robot name="a">' + "<a>" * 100_000 + "</a>" * 100_000 + "</robot>")
    deep_urdf = write("deep.urdf", '<robot name="a"><link name="b">' + "<x>" * 10_000 + "</x>" * 10_000 + "</link></robot>")
    empty_group = write("empty.srdf", '<robot name="test_arm"><group name="none"></group></robot>')
    twice = write("twice.srdf", '<robot name="test_arm"><group name="g"><joint name="j1"/></group><group name="g"><joint name="j2"/></group></robot>')
    fixed = write("fixed.urdf", '<robot name="r"><link name="base"/><link name="a"/><joint name="f" type="fixed"><parent link="base"/><child link="a"/></joint></robot>')
    huge = write("huge.urdf", '<robot name="r"><link name="base"><visual><geometry><box size="1e300 1 1"/></geometry></visual></link><link name="a"/><joint name="j" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    many = lambda width: np.broadcast_to(np.zeros(width), (10**9, width))

    def self_model(edit):
        copy = tmp_path / f"model{len(list(tmp_path.iterdir()))}"
        shutil.copytree(folder / "model", copy)
        edit(copy)
        return lambda: selfmodel.SelfModel.load(copy).predict(np.zeros((1, nk.inputs)))

    cases = [
        ("fk of 10^9 broadcast rows", lambda: robot.fk(many(6)), "call it in batches"),
        ("jacobian of 10^9 rows", lambda: robot.jacobian(many(6)), "call it in batches"),
        ("render of 10^9 rows", lambda: robot.render(many(6)), "call it in batches"),
        ("solve of 10^9 rows", lambda: selfmodel.IkSolver.load(str(model)).solve(many(7)), "call it in batches"),
        ("predict of 10^9 rows", lambda: nk.predict(many(nk.inputs)), "call it in batches"),
        ("an SRDF nested 100,000 deep", lambda: selfmodel.Robot.from_urdf(str(urdf), group="g", srdf=deep_srdf), "nest 100001 deep"),
        ("a URDF nested 10,000 deep", lambda: selfmodel.Robot.from_urdf(deep_urdf), "nest 10002 deep"),
        ("a group without joints", lambda: selfmodel.Robot.from_urdf(str(urdf), group="none", srdf=empty_group), "no movable joints"),
        ("tips at the root", lambda: selfmodel.Robot.from_urdf(str(urdf), tips=["base"]), "no movable joints"),
        ("an all-fixed robot", lambda: selfmodel.Robot.from_urdf(fixed, tip="a"), "no movable joints"),
        ("an SRDF that is a FIFO", lambda: selfmodel.Robot.from_urdf(str(urdf), group="g", srdf=str(fifo)), "not a regular file"),
        ("an SRDF that is /dev/zero", lambda: selfmodel.Robot.from_urdf(str(urdf), group="g", srdf="/dev/zero"), "not a regular file"),
        ("a group named twice", lambda: selfmodel.Robot.from_urdf(str(urdf), group="g", srdf=twice), "defined twice"),
        ("a box of 1e300 m", lambda: selfmodel.Robot.from_urdf(huge), "at most 10000 m, got 1e300"),
        ("model.json a FIFO", self_model(lambda d: _replace_by_fifo(d / "model.json")), "not a regular file"),
        ("model.bpk a FIFO", self_model(lambda d: _replace_by_fifo(d / "model.bpk")), "not a regular file"),
        ("probe.npz a FIFO", self_model(lambda d: _replace_by_fifo(d / "probe.npz")), "not a regular file"),
        ("model.json: another image size", self_model(lambda d: _edit_json(d / "model.json", lambda j: j.update(image=[64, 64]))), "its weights draw 32x32"),
        ("model.json: the same pixels in another shape", self_model(lambda d: _edit_json(d / "model.json", lambda j: (j.update(image=[16, 64]), j["model"].update(image=[16, 64])))), "probe poses"),
        ("model.json: another input count", self_model(lambda d: _edit_json(d / "model.json", lambda j: j.update(inputs=n + 1))), f"names {n} joints for {n + 1} inputs"),
        ("model.json: joint names for other inputs", self_model(lambda d: _edit_json(d / "model.json", lambda j: j.update(joint_names=j["joint_names"][:-1]))), f"names {n - 1} joints"),
        ("model.json without the weights' hash", self_model(lambda d: _edit_json(d / "model.json", lambda j: j.pop("weights_fnv"))), "edited or damaged"),
        ("NaN weights with their hash recomputed", self_model(_nan_weights_with_their_hash), "probe poses"),
        ("an empty probe", self_model(lambda d: np.savez(d / "probe.npz", **{k: v[:0] for k, v in np.load(d / "probe.npz").items()})), "0 values"),
    ]
    failures = []
    for name, case, says in cases:
        try:
            case()
            failures.append(f"{name}: accepted")
        except ValueError as e:
            if says not in str(e) or "\n" in str(e):
                failures.append(f"{name}: {e!r} (expected one line with {says!r})")
    assert not failures, "\n".join(failures)
