"""Cross-checks of stages against pymeshlab, open3d and libigl."""
