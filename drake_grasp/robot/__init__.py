"""The robot: arm specs and loading, the hand, the task, the one plant assembly and its configuration."""
