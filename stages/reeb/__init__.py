"""Level sets, Reeb graphs, pruning and export of skeletons (thesis Algorithms 1 and 4)."""
