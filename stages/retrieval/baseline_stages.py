"""The baseline descriptors (D2, spherical harmonics, ShapeDNA) as pipeline stages."""

from __future__ import annotations

from topomatch.stages.retrieval.baselines import d2, shapedna, spherical_harmonics
from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult
from topomatch.pipeline.registry import stage


@stage("d2", params=d2.D2Params, version=1, consumes=("mesh",), produces=("descriptor",))
def d2_stage(mesh, *, params: d2.D2Params) -> DescriptorResult:
    """D2 shape distribution (Osada et al. 2002): histogram of random surface-point distances."""
    return DescriptorResult(Descriptor("vector", d2.descriptor(mesh, params)))


@stage("spherical_harmonics", params=spherical_harmonics.SphericalHarmonicsParams, version=1, consumes=("mesh",),
       produces=("descriptor",))
def spherical_harmonics_stage(mesh, *, params: spherical_harmonics.SphericalHarmonicsParams) -> DescriptorResult:
    """Rotation-invariant spherical harmonic descriptor (Kazhdan et al. 2003)."""
    return DescriptorResult(Descriptor("vector", spherical_harmonics.descriptor(mesh, params).ravel()))


@stage("shapedna", params=shapedna.ShapeDNAParams, version=3, consumes=("mesh",), produces=("descriptor",))
def shapedna_stage(mesh, *, params: shapedna.ShapeDNAParams) -> DescriptorResult:
    """ShapeDNA (Reuter et al. 2006): normalised leading Laplace-Beltrami eigenvalues."""
    return DescriptorResult(Descriptor("vector", shapedna.descriptor(mesh, params)))
