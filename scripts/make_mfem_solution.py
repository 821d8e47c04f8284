"""A real high-order FE solution from a real FE code, for `isobar fe`'s end-to-end test:
MFEM (PyPI `mfem`, serial module) solves the Poisson problem -Δu = 1, u = 0 on the
boundary, with third-order H1 elements on a 3×3×3 hexahedral mesh of the unit cube whose
nodes are warped into a curved (third-order) domain, and saves it through
ParaViewDataCollection with SetHighOrderOutput(True): VTU Lagrange hexahedra (type 72)
with the point array `u`.

    python -m venv /tmp/fe2venv && /tmp/fe2venv/bin/pip install mfem
    /tmp/fe2venv/bin/python scripts/make_mfem_solution.py rust-core/data/fe/mfem_poisson_q3.vtu
"""

import math
import os
import shutil
import sys
import tempfile

import mfem.ser as mfem

ORDER = 3
N = 3


class Warp(mfem.VectorPyCoefficient):
    """A smooth bending of the unit cube (keeps every element positively oriented)."""

    def __init__(self):
        super().__init__(3)

    def EvalValue(self, x):
        return [
            x[0] + 0.12 * math.sin(math.pi * x[1]) * x[2],
            x[1] + 0.10 * math.sin(math.pi * x[0]),
            x[2] + 0.08 * math.sin(math.pi * x[0]) * math.sin(math.pi * x[1]),
        ]


def main(out):
    mesh = mfem.Mesh.MakeCartesian3D(N, N, N, mfem.Element.HEXAHEDRON, 1.0, 1.0, 1.0)
    mesh.SetCurvature(ORDER)
    mesh.Transform(Warp())
    fec = mfem.H1_FECollection(ORDER, 3)
    fes = mfem.FiniteElementSpace(mesh, fec)
    ess_bdr = mfem.intArray([1] * mesh.bdr_attributes.Max())
    ess_tdof = mfem.intArray()
    fes.GetEssentialTrueDofs(ess_bdr, ess_tdof)
    one = mfem.ConstantCoefficient(1.0)
    b = mfem.LinearForm(fes)
    b.AddDomainIntegrator(mfem.DomainLFIntegrator(one))
    b.Assemble()
    x = mfem.GridFunction(fes)
    x.Assign(0.0)
    a = mfem.BilinearForm(fes)
    a.AddDomainIntegrator(mfem.DiffusionIntegrator(one))
    a.Assemble()
    A = mfem.OperatorPtr()
    B = mfem.Vector()
    X = mfem.Vector()
    a.FormLinearSystem(ess_tdof, x, b, A, X, B)
    M = mfem.GSSmoother(mfem.OperatorHandle2SparseMatrix(A))
    mfem.PCG(A, M, B, X, 0, 2000, 1e-24, 0.0)
    a.RecoverFEMSolution(X, b, x)
    print("unknowns", fes.GetTrueVSize(), "max u", x.Max())
    tmp = tempfile.mkdtemp()
    pd = mfem.ParaViewDataCollection("poisson", mesh)
    pd.SetPrefixPath(tmp)
    pd.SetLevelsOfDetail(ORDER)
    pd.SetHighOrderOutput(True)
    pd.SetDataFormat(mfem.VTKFormat_BINARY)
    pd.RegisterField("u", x)
    pd.SetCycle(0)
    pd.SetTime(0.0)
    pd.Save()
    vtu = os.path.join(tmp, "poisson", "Cycle000000", "proc000000.vtu")
    shutil.copy(vtu, out)
    shutil.rmtree(tmp)
    print("wrote", out, os.path.getsize(out), "bytes")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "rust-core/data/fe/mfem_poisson_q3.vtu")
