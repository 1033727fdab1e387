"""Data on disk: resumable sharded jobs (local workers or Ray) and the grasp-trial data set reader."""
