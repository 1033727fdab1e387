"""The programs (command-line entry points); nothing outside `apps` imports them.

Each runs as `python -m drake_grasp <command>` or `drake-grasp <command>` (`apps.commands`);
`python -m drake_grasp.simulate` and `python -m drake_grasp.collect_reachability` stay valid.
"""
