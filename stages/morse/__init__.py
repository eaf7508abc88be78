"""Morse functions on mesh vertices: mixture distance (thesis ch. 3), height, geodesic distance.

The Fiedler vector (thesis ch. 4) lives in :mod:`topomatch.stages.spectral`; the ``morse``
stage (:mod:`topomatch.stages.morse.stage`) dispatches to all of them.
"""
