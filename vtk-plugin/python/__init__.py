"""isobar for VTK: exact isosurfaces of SPH particle data (Marching Correctors, or the
adaptive 3-level grid), isovalue sliding on image data (ISOSLIDER), and point samples of
isosurfaces of high-order Lagrange cells (particle system).

Built against Debian's VTK 9.1 (python3-vtk9); import it only next to that VTK.

    from isobar_vtk import vtkIsobarSPHIsosurface, vtkIsobarVolumeSlider, vtkIsobarFESamples
"""

from .IsobarVTK import vtkIsobarFESamples, vtkIsobarSPHIsosurface, vtkIsobarVolumeSlider  # noqa: F401

__all__ = ["vtkIsobarFESamples", "vtkIsobarSPHIsosurface", "vtkIsobarVolumeSlider"]
