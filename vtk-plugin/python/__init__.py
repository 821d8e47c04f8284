"""isobar for VTK: exact isosurfaces of SPH particle data (Marching Correctors, or the
adaptive 3-level grid) and isovalue sliding on image data (ISOSLIDER).

Built against Debian's VTK 9.1 (python3-vtk9); import it only next to that VTK.

    from isobar_vtk import vtkIsobarSPHIsosurface, vtkIsobarVolumeSlider
"""

from .IsobarVTK import vtkIsobarSPHIsosurface, vtkIsobarVolumeSlider  # noqa: F401

__all__ = ["vtkIsobarSPHIsosurface", "vtkIsobarVolumeSlider"]
