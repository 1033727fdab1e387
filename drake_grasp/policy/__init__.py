"""Where a grasp is sampled and scored: sampling, the scorers (RAND, RP, CNN, CNN_RP, GPD, VPG), selection."""
