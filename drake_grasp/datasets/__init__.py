"""Data sets on disk: resumable sharded jobs, reachability labels and grasp trials."""
