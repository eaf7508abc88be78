"""Matching skeletons: endpoint features, correspondence, dissimilarity (thesis §3.3-3.4)."""
