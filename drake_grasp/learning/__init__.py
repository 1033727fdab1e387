"""The learned predictors: features, voxels, networks, one training loop, loaders and metrics."""
