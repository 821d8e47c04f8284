/**
 * @class   vtkIsobarSPHIsosurface
 * @brief   exact isosurfaces of SPH particle data (Marching Correctors)
 *
 * The input is any vtkPointSet whose points are SPH particles and whose point data holds
 * the particle arrays, or a vtkPartitionedDataSet of such point sets (one dataset in
 * pieces: its partitions' particles make one surface). The output is a triangle mesh whose vertices lie on the level set
 * of the SPH interpolant itself (to a relative tolerance, 1e-6 by default), with
 * "Normals" from the SPH gradient, "SumOfWeights" (Marching Correctors), the carried arrays
 * interpolated with the same kernel, and "Isovalue" when several isovalues are given.
 * Points are doubles.
 *
 * All numeric work is done by the isobar core (Rust, linked statically through
 * isobar.h); this class converts arrays, maps its parameters onto IsobarSphParams,
 * reports progress, honours AbortExecute, turns core errors into vtkErrorMacro with
 * an empty output and the core's warnings (isobar_surface_warnings) into vtkWarningMacro,
 * one a line, keeping the output.
 *
 * Field: the sum of weights sum_j V_j W (the free surface; isovalue 0.6 with computed
 * volumes is splashsurf's surface) or the point array chosen with
 * SetInputArrayToProcess(0, ...): a scalar as is, a vector as its magnitude
 * (FieldComponent = -1) or one component (FieldComponent = k).
 *
 * Parallel runs: with a multi-process controller of more than one process (pvbatch or
 * pvserver under MPI) the ranks agree on the particles' global bounds and smallest and
 * largest h, cut space into one slab per rank along the longest axis (about equal
 * particle counts), send each rank the particles of its slab plus a halo of two kernel
 * supports and one cell (ghost points skipped), and extract on a lattice they share,
 * each keeping the surface of the cells whose lowest corner lies in its slab. By default
 * the lattice is the grid a single process would use on all particles, so the pieces
 * together are the single-process surface (vertex positions to rounding), with no
 * duplicate triangles; vertices on the cuts appear once in each adjacent piece.
 */

#ifndef vtkIsobarSPHIsosurface_h
#define vtkIsobarSPHIsosurface_h

#include "IsobarVTKModule.h" // For export macro
#include "vtkPolyDataAlgorithm.h"

#include <string> // For ErrorMessage
#include <vector> // For Isovalues

class vtkDataArraySelection;
class vtkMultiProcessController;
struct IsobarSphParams;

class ISOBARVTK_EXPORT vtkIsobarSPHIsosurface : public vtkPolyDataAlgorithm
{
public:
  static vtkIsobarSPHIsosurface* New();
  vtkTypeMacro(vtkIsobarSPHIsosurface, vtkPolyDataAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// What is contoured.
  enum FieldModes
  {
    SUM_OF_WEIGHTS = 0, ///< sum_j V_j W(x - x_j): the free surface
    POINT_ARRAY = 1     ///< the array chosen with SetInputArrayToProcess(0, ...)
  };

  /// SPH kernels (the core's ISOBAR_KERNEL_* values).
  enum Kernels
  {
    CUBIC = 0,     ///< Monaghan's cubic spline, support 2h
    WENDLAND = 1,  ///< Wendland C2, support 2h
    QUINTIC = 2,   ///< Morris' quintic spline, support 3h
    QUADRATIC = 3  ///< Johnson's quadratic kernel, support 2h
  };

  ///@{
  /// SUM_OF_WEIGHTS (default) or POINT_ARRAY.
  vtkSetClampMacro(FieldMode, int, SUM_OF_WEIGHTS, POINT_ARRAY);
  vtkGetMacro(FieldMode, int);
  ///@}

  ///@{
  /// For a multi-component input array: -1 (default) contours its magnitude, k >= 0 its
  /// component k. Ignored for one-component arrays.
  vtkSetMacro(FieldComponent, int);
  vtkGetMacro(FieldComponent, int);
  ///@}

  ///@{
  /// Isovalues: one surface each, all in one output. Default: one value, 0.6.
  void SetNumberOfIsovalues(int count);
  int GetNumberOfIsovalues();
  void SetIsovalue(int index, double value);
  double GetIsovalue(int index);
  ///@}

  ///@{
  /// Constant smoothing length h, used when no smoothing-length array is named. 0 (the
  /// default) means: use the point array "h", "smoothing_length" or "hsml", whichever
  /// exists first (as the isobar CLI does); with none, RequestData reports an error.
  vtkSetMacro(SmoothingLength, double);
  vtkGetMacro(SmoothingLength, double);
  ///@}

  ///@{
  /// Per-particle smoothing-length array (empty or NULL: none).
  vtkSetStringMacro(SmoothingLengthArrayName);
  vtkGetStringMacro(SmoothingLengthArrayName);
  ///@}

  ///@{
  /// Multiplies every smoothing length (1, 0.75, 0.5 ... for quick previews).
  vtkSetMacro(HScale, double);
  vtkGetMacro(HScale, double);
  ///@}

  ///@{
  /// Particle volumes: a volume array (m/rho) wins; else a density array with a mass
  /// (MassArrayName or Mass); else the core computes densities from the particles.
  vtkSetStringMacro(VolumeArrayName);
  vtkGetStringMacro(VolumeArrayName);
  vtkSetStringMacro(DensityArrayName);
  vtkGetStringMacro(DensityArrayName);
  vtkSetStringMacro(MassArrayName);
  vtkGetStringMacro(MassArrayName);
  ///@}

  ///@{
  /// Constant particle mass (0: none).
  vtkSetMacro(Mass, double);
  vtkGetMacro(Mass, double);
  ///@}

  ///@{
  /// Divide the field by the sum of weights (Shepard normalisation). Default off.
  vtkSetMacro(Shepard, vtkTypeBool);
  vtkGetMacro(Shepard, vtkTypeBool);
  vtkBooleanMacro(Shepard, vtkTypeBool);
  ///@}

  ///@{
  /// One of Kernels; default CUBIC.
  vtkSetClampMacro(Kernel, int, CUBIC, QUADRATIC);
  vtkGetMacro(Kernel, int);
  ///@}

  ///@{
  /// Virtual cell size in units of the smallest smoothing length (core default 0.5).
  vtkSetMacro(GridFactor, double);
  vtkGetMacro(GridFactor, double);
  ///@}

  /// How the surface is extracted.
  enum Methods
  {
    MARCHING_CORRECTORS = 0, ///< vertices on the level set, trimming, MPI pieces
    ADAPTIVE = 1             ///< crack-free 3-level grid: far fewer triangles, one process
  };

  ///@{
  /// MARCHING_CORRECTORS (default) or ADAPTIVE. The adaptive surface (isobar's 3-level
  /// grid, cells of GridFactor at the finest level, four times that at the coarsest) uses
  /// one isovalue, carries Normals and the carried arrays and runs in one process;
  /// Correct, Trim and FullGrid apply to Marching Correctors.
  vtkSetClampMacro(Method, int, MARCHING_CORRECTORS, ADAPTIVE);
  vtkGetMacro(Method, int);
  ///@}

  ///@{
  /// Adaptive method: coarse cells holding 1 to this many particles (splashes) are refined
  /// to the finest level (the paper's rule: 1; core default 0, none: the error criterion
  /// alone decides).
  vtkSetMacro(SplashThreshold, int);
  vtkGetMacro(SplashThreshold, int);
  ///@}

  ///@{
  /// Adaptive method, error criterion added to the splash one: each cell at the surface
  /// takes the lowest level whose surface lies within this many finest cells of the
  /// finest level's there (core default; 0 turns it off).
  vtkSetMacro(MaxError, double);
  vtkGetMacro(MaxError, double);
  ///@}

  ///@{
  /// Adaptive method: halvings n of a level-3 edge when placing its surface point (n+1 on
  /// level 2, n+2 on level 1, so shared points coincide; core default 5). 0 places level-3
  /// points linearly between the finest nodes, as marching cubes does: faster, coarser.
  vtkSetMacro(BisectionIterations, int);
  vtkGetMacro(BisectionIterations, int);
  ///@}

  ///@{
  /// Where the work runs, ISOBAR_BACKEND_CPU (0, default), ISOBAR_BACKEND_GPU (1, wgpu;
  /// an error when there is no adapter) or ISOBAR_BACKEND_AUTO (2, a hardware GPU when
  /// there is one): Marching Correctors' seed-cell neighbour search (same surface on
  /// every back end; FullGrid refuses GPU), or the Adaptive method's grids. When Auto
  /// runs on the CPU, a warning says why (as the CLI's "backend auto: running on the CPU
  /// (...)") and the output's field data carries the reason as the string array
  /// "IsobarBackendNote".
  vtkSetClampMacro(Backend, int, 0, 2);
  vtkGetMacro(Backend, int);
  ///@}

  ///@{
  /// Correct vertices onto the level set (default on); off gives a linear preview.
  vtkSetMacro(Correct, vtkTypeBool);
  vtkGetMacro(Correct, vtkTypeBool);
  vtkBooleanMacro(Correct, vtkTypeBool);
  ///@}

  ///@{
  /// Relative tolerance of the correction (core default 1e-6).
  vtkSetMacro(Tolerance, double);
  vtkGetMacro(Tolerance, double);
  ///@}

  ///@{
  /// Trim the surface at free surfaces where the sum of weights falls below the
  /// thresholds (node: cells discarded; vertex: triangles clipped). Default on; never
  /// applied to the SUM_OF_WEIGHTS field itself (it would cut the surface away).
  vtkSetMacro(Trim, vtkTypeBool);
  vtkGetMacro(Trim, vtkTypeBool);
  vtkBooleanMacro(Trim, vtkTypeBool);
  vtkSetMacro(TrimNode, double);
  vtkGetMacro(TrimNode, double);
  vtkSetMacro(TrimVertex, double);
  vtkGetMacro(TrimVertex, double);
  ///@}

  ///@{
  /// Vertex normals from the SPH gradient (default on).
  vtkSetMacro(ComputeNormals, vtkTypeBool);
  vtkGetMacro(ComputeNormals, vtkTypeBool);
  vtkBooleanMacro(ComputeNormals, vtkTypeBool);
  ///@}

  ///@{
  /// Memory the core may use for extent-sized structures, in GiB (core default 4).
  vtkSetMacro(MemoryBudget, double);
  vtkGetMacro(MemoryBudget, double);
  ///@}

  ///@{
  /// Resample onto a full grid and run marching cubes instead (the core's baseline, for
  /// comparisons). Default off.
  vtkSetMacro(FullGrid, vtkTypeBool);
  vtkGetMacro(FullGrid, vtkTypeBool);
  vtkBooleanMacro(FullGrid, vtkTypeBool);
  ///@}

  ///@{
  /// Put the virtual grid on the lattice LatticeOrigin + (i, j, k) x cell for integers
  /// i, j, k, with cell = LatticeCellSize, or Grid Factor x the smallest h when that is 0
  /// (default off: a single process uses the data's own grid, as the CLI; a parallel run
  /// uses the lattice of that grid over all ranks' particles). A lattice fixed across
  /// frames keeps the grid still in time.
  vtkSetMacro(FixedLattice, vtkTypeBool);
  vtkGetMacro(FixedLattice, vtkTypeBool);
  vtkBooleanMacro(FixedLattice, vtkTypeBool);
  vtkSetVector3Macro(LatticeOrigin, double);
  vtkGetVector3Macro(LatticeOrigin, double);
  vtkSetMacro(LatticeCellSize, double);
  vtkGetMacro(LatticeCellSize, double);
  ///@}

  ///@{
  /// This rank's piece in the last parallel execution: the slab axis (-1 in a
  /// single-process run), the slab [PieceBounds[0], PieceBounds[1]) along it (+-DBL_MAX
  /// on the outer sides) and the particles it extracted from (own slab plus halo).
  vtkGetMacro(PieceAxis, int);
  vtkGetVector2Macro(PieceBounds, double);
  vtkGetMacro(PieceParticles, vtkIdType);
  ///@}

  /// Point arrays interpolated onto the surface: enable them by name. None by default.
  vtkGetObjectMacro(CarriedArraySelection, vtkDataArraySelection);

  ///@{
  /// The controller of a parallel run (default: the global controller).
  virtual void SetController(vtkMultiProcessController*);
  vtkGetObjectMacro(Controller, vtkMultiProcessController);
  ///@}

  /// The last update's errors, a line each (of each failing block of a multi-block input;
  /// "" when the update succeeded).
  const char* GetErrorMessage() { return this->ErrorMessage.c_str(); }

  /// The field string handed to the core for the current settings, given the number of
  /// components of the input array ("SumOfWeights", "NAME", "NAME:mag" or "NAME:K").
  std::string FieldString(const char* arrayName, int components) const;

  vtkMTimeType GetMTime() override;

protected:
  vtkIsobarSPHIsosurface();
  ~vtkIsobarSPHIsosurface() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  /// Reports `message` through vtkErrorMacro and remembers it for GetErrorMessage.
  void Fail(const std::string& message);
  /// The first setting outside its range, as a message naming it ("" when all are fine):
  /// a bad value is refused, not clamped to another that would run without a word.
  std::string CheckSettings() const;

  /// Each line of `warnings` (isobar_surface_warnings: one a line, "" for none) as its
  /// own vtkWarningMacro, so that ParaView's Output Messages lists them one by one. In a
  /// parallel run `crossed` holds every rank's triangles per isovalue: "no surface at
  /// isovalue" then speaks of this rank's slab, and is left out for an isovalue another
  /// slab has triangles of. Empty `crossed`: a serial run, every line is shown.
  void Warn(const std::string& warnings, const std::vector<vtkIdType>& crossed);

  /// With Backend Auto on a machine where Auto runs on the CPU: the core's reason
  /// (isobar_auto_backend_note) as a warning and as the output's field data string array
  /// "IsobarBackendNote". Returns an error message or "".
  std::string NoteAutoBackend(vtkPolyData* output);

  /// Progress from the core: UpdateProgress, and whether to abort.
  bool ReportProgress(double fraction, const char* phase);

  /// The enabled carried arrays, in selection order.
  std::vector<std::string> CarriedArrayNames();

  /// The input array's name in POINT_ARRAY mode ("" otherwise or when none is set).
  std::string FieldArrayName();

  /// The core's parameters for these settings; the strings must outlive the result.
  IsobarSphParams MakeParams(const std::string& field, const std::string& hArray,
    const std::vector<const char*>& carried) const;

  int FieldMode;
  int FieldComponent;
  std::vector<double> Isovalues;
  double SmoothingLength;
  char* SmoothingLengthArrayName;
  double HScale;
  char* VolumeArrayName;
  char* DensityArrayName;
  char* MassArrayName;
  double Mass;
  vtkTypeBool Shepard;
  int Kernel;
  double GridFactor;
  int Method;
  int SplashThreshold;
  double MaxError;
  int BisectionIterations;
  int Backend;
  vtkTypeBool Correct;
  double Tolerance;
  vtkTypeBool Trim;
  double TrimNode;
  double TrimVertex;
  vtkTypeBool ComputeNormals;
  double MemoryBudget;
  vtkTypeBool FullGrid;
  vtkTypeBool FixedLattice;
  double LatticeOrigin[3];
  double LatticeCellSize;
  int PieceAxis;
  double PieceBounds[2];
  vtkIdType PieceParticles;
  vtkDataArraySelection* CarriedArraySelection;
  vtkMultiProcessController* Controller;
  std::string ErrorMessage;
  double LastProgress;

private:
  vtkIsobarSPHIsosurface(const vtkIsobarSPHIsosurface&) = delete;
  void operator=(const vtkIsobarSPHIsosurface&) = delete;

  friend struct vtkIsobarSPHIsosurfaceProgress;
};

#endif
