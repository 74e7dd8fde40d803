#!/usr/bin/env python3
"""Render joint poses with PyBullet, the simulator of both self-modeling papers, so that our
ray caster can be compared with it (`mesh_fidelity --pybullet OUT.npz`).

Setup (not needed by the project itself):
    python3 -m venv /tmp/pb && /tmp/pb/bin/pip install numpy pybullet
Use:
    /tmp/pb/bin/python scripts/pybullet_render.py --angles ANGLES.csv --out data/pybullet.npz

The scene is the papers': the URDF's base at [0, 0, -0.108] with yaw -pi/2, camera at
[1, 0, 0] looking at the origin with up +z, 42 degree field of view, 100x100 pixels, the
TinyRenderer (no GPU). Silhouettes come from the segmentation mask (robot pixels = 255).
Angles: CSV, one row per pose, degrees (a header line is allowed).
"""
import argparse
import os

import numpy as np
import pybullet as p


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    default_urdf = os.path.join(here, "..", "..", "shared", "robots", "4dof_1st", "urdf", "4dof_1st.urdf")
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--angles", required=True, help="CSV of joint angles in degrees, one row per pose")
    ap.add_argument("--urdf", default=default_urdf)
    ap.add_argument("--out", required=True, help="output .npz (images, angles, focal, poses)")
    ap.add_argument("--size", type=int, default=100)
    ap.add_argument("--fov", type=float, default=42.0)
    args = ap.parse_args()

    rows = []
    with open(args.angles) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            try:
                rows.append([float(v) for v in line.split(",")])
            except ValueError:
                if rows:
                    raise
    angles = np.array(rows, dtype=np.float64)

    p.connect(p.DIRECT)
    urdf = os.path.abspath(args.urdf)
    # package://4dof_1st/... resolves against the folder holding the package.
    p.setAdditionalSearchPath(os.path.dirname(os.path.dirname(os.path.dirname(urdf))))
    robot = p.loadURDF(urdf, basePosition=[0, 0, -0.108],
                       baseOrientation=p.getQuaternionFromEuler([0, 0, -np.pi / 2]), useFixedBase=True)
    movable = [j for j in range(p.getNumJoints(robot)) if p.getJointInfo(robot, j)[2] != p.JOINT_FIXED]
    assert angles.shape[1] == len(movable), f"{angles.shape[1]} angle columns for {len(movable)} joints"
    view = p.computeViewMatrix([1, 0, 0], [0, 0, 0], [0, 0, 1])
    proj = p.computeProjectionMatrixFOV(args.fov, 1.0, 0.1, 10.0)
    images = np.zeros((len(angles), args.size, args.size), np.uint8)
    for i, q in enumerate(angles):
        for j, a in zip(movable, q):
            p.resetJointState(robot, j, np.deg2rad(a))
        _, _, _, _, seg = p.getCameraImage(args.size, args.size, view, proj, renderer=p.ER_TINY_RENDERER)
        seg = np.asarray(seg).reshape(args.size, args.size)
        images[i] = np.where((seg & ((1 << 24) - 1)) == robot, 255, 0)
    focal = args.size / 2 / np.tan(np.deg2rad(args.fov) / 2)
    pose = np.array([[0, 0, 1, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]], np.float64)
    tmp = args.out + ".tmp.npz"
    np.savez_compressed(tmp, images=images, angles=angles, focal=np.float64(focal),
                        poses=np.repeat(pose[None], len(angles), 0))
    os.replace(tmp, args.out)
    print(f"pybullet: rendered {len(angles)} poses, mean occupancy {images.mean() / 255:.4f}, wrote {args.out}")


if __name__ == "__main__":
    main()
