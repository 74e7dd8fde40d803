#!/usr/bin/env python3
"""Write data/fixtures/papers_format.npz: a 3-sample dataset in the layout of the papers'
PyTorch code (np.savez, uncompressed; images uint8, angles float64 degrees, focal, poses),
without depth or n_train, so the tests check that such files load."""
import numpy as np

images = np.zeros((3, 100, 100), np.uint8)
images[:, 40:60, 45:55] = 255
images[1, 20:40, 50:52] = 255
angles = np.array([[0, 0, 0, 0], [10, -20, 30, -40], [45.5, 12.25, -3, 89]], np.float64)
pose = np.array([[0, 0, 1, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]], np.float64)
np.savez("data/fixtures/papers_format.npz", images=images, angles=angles,
         focal=np.float64(130.2545), poses=np.repeat(pose[None], 3, 0))
