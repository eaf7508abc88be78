"""Spectral geometry (thesis ch. 4): the FEM Laplace–Beltrami operator and its smallest eigenpairs.

- :mod:`topomatch.stages.spectral.laplacian`: cotangent stiffness ``Q = -igl.cotmatrix`` and mass
  ``K`` (consistent FEM "area matrix" or Voronoi lumped), with input validation;
  stage ``laplacian``.
- :mod:`topomatch.stages.spectral.eigen`: smallest generalised eigenpairs ``Q phi = lambda K phi``
  (shift-invert block Krylov, multilevel, LOBPCG + AMG, dense) and the sign rule.
- the Fiedler vector ``phi2`` as a Morse function (stage ``fiedler``) is :mod:`topomatch.stages.morse.fiedler`.

See ``docs/spectral.md`` for the design and the measured speed.
"""
