"""isobar for VTK: exact isosurfaces of SPH particle data (Marching Correctors).

Built against Debian's VTK 9.1 (python3-vtk9); import it only next to that VTK.

    from isobar_vtk import vtkIsobarSPHIsosurface
"""

from .IsobarVTK import vtkIsobarSPHIsosurface  # noqa: F401

__all__ = ["vtkIsobarSPHIsosurface"]
