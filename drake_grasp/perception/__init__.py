"""Perception: depth -> world cloud -> crop -> table removal; camera files, depth loaders, RealSense."""
