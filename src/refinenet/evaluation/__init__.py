"""Floor 5, measuring normals against ground truth (docs/algorithm.md §12): angular error statistics, category
aggregation, and the paper's tables as CSV and booktabs LaTeX."""
