"""The cross-view tracker of Chen et al. (CVPR 2020) and its baseline: numpy and scipy only."""
