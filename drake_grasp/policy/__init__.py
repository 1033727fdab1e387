"""Choosing and executing grasps: sampling, scorers (the policies), selection, the executive, episodes."""
