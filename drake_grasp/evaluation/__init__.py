"""Evaluations: typed configuration and presets, closed-loop runs and their reports and statistics, and
the jobs that label data by evaluating candidates (grasp trials in physics, planning-success labels)."""
