"""The paper's learned baselines in our simulator: GPD (ten Pas et al. 2017), VPG (Zeng et al. 2018)."""
