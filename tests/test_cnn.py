import numpy as np
import torch

from drake_grasp.cnn import GraspCNN
from drake_grasp.sampling import sample_grasps
from drake_grasp.voxels import voxelize


def test_architecture_sizes():
    assert GraspCNN(first_stride=2)(torch.zeros(3, 32, 32, 32)).shape == (3,)
    assert GraspCNN(first_stride=1)(torch.zeros(2, 32, 32, 32)).shape == (2,)
    params = sum(p.numel() for p in GraspCNN(first_stride=2).parameters())
    assert 0.8e6 < params < 1.0e6  # the VoxNet-style variant


def test_loss_falls_on_a_small_dataset_the_test_makes():
    """Blocks narrower than the 80 mm jaw opening (label 1) against wider ones (label 0)."""
    rng = np.random.default_rng(0)
    grids, labels = [], []
    for _ in range(64):
        width = rng.uniform(0.02, 0.12)
        u = rng.uniform(-0.5, 0.5, (1500, 3)) * [0.05, width, 0.04]
        points = u + [0.5, 0.0, 0.02]
        X = sample_grasps(points[points[:, 2] > 0.035], 1, (0, 0), rng)
        X[0, :3, :3] = np.diag([1.0, -1.0, -1.0])  # close across the block's width
        grids.append(voxelize(points, X)[0])
        labels.append(float(width < 0.08))
    x, y = torch.from_numpy(np.stack(grids)), torch.tensor(labels)
    torch.manual_seed(0)
    model = GraspCNN()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    loss_fn = torch.nn.BCEWithLogitsLoss()
    losses = []
    for _ in range(15):
        optimizer.zero_grad()
        loss = loss_fn(model(x), y)
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.6 * losses[0]
