"""Experiments over many runs: the benchmark, sweeps (serial, pooled or on Ray), the paper's ablations, the tracker
comparison and the Table 5 reproduction, with their reports."""
