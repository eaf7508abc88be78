"""Baseline shape descriptors measured side by side with the thesis methods.

Each module has a frozen params class (a :class:`topomatch.pipeline.contract.Params`), a pure
``descriptor(mesh, params) -> np.ndarray``, a ``distance(a, b) -> float`` and a vectorised
``distance_matrix(X, Y=None) -> (n, m)``:

============================  =======================================  ==================  ========
module                        descriptor                               shape               distance
============================  =======================================  ==================  ========
:mod:`.d2`                    D2 shape distribution (Osada 2002)       (bins,) = (64,)     L1
:mod:`.spherical_harmonics`   rotation-invariant SH (Kazhdan 2003)     (radii, L+1)        L2
                                                                       = (32, 17)
:mod:`.shapedna`              ShapeDNA (Reuter 2006), lambda_i A / i   (k,) = (30,)        L2
:mod:`.sdgdm`                 SD-GDM (Smeets 2012), log of the         (k - 1,) = (39,)    L2
                              geodesic distance matrix's singular
                              values over the largest
:mod:`.light_field`           light field (Chen 2003): Zernike and     (L * 10 * 46,)      min over
                              Fourier features of dodecahedron         = (2300,)           rotations
                              silhouettes                                                  of L1
============================  =======================================  ==================  ========

:mod:`.sampling` holds the shared surface sampler. Each module also defines its pipeline stage
(``d2``, ``spherical_harmonics``, ``shapedna``, ``sdgdm``, ``light_field``); the retrieval methods that use them are records of
:mod:`topomatch.stages.retrieval.catalogue`.
"""

