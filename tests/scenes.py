"""Small scenario files the tests share."""


def one_cube_yaml(max_attempts: int) -> str:
    """One object at (0.5, 0.05), top-down candidates only, a few attempts: a quick closed loop."""
    return ("name: one_cube\nclusters:\n  - centre: [0.5, 0.05]\n    radius: 0.0\n    count: 1\n"
            f"settle_time: 0.6\ngamma_deg: [0.0, 0.0]\nnum_candidates: 50\nmax_attempts: {max_attempts}\n")
