"""The programs (command-line entry points); nothing outside `apps` imports them.

Each is run as `python -m drake_grasp.<name>` or as the console script `drake-grasp-<name>`.
"""
