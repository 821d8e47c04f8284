/**
 * @class   vtkIsobarFESamples
 * @brief   isosurface of a high-order finite-element field as oriented point samples
 *
 * The input is a vtkUnstructuredGrid of Lagrange cells (VTK_LAGRANGE_TETRAHEDRON,
 * _HEXAHEDRON, _WEDGE, any order, with HigherOrderDegrees when present) or of VTK's linear
 * and quadratic tetrahedra, hexahedra, voxels and wedges (which the core reads as the
 * Lagrange cells of the same functions), and a point
 * scalar array (SetInputArrayToProcess(0, ...), else the active scalars). The isosurface
 * Field = Isovalue of the elements' own polynomials is sampled by isobar's particle
 * system (Meyer et al. 2007): every sample lies on the level set to Tolerance, no grid
 * resampling and no tessellation of the curved cells. The output is a vtkPolyData of
 * vertices with "Normals" (unit, along the field's gradient), "Radius" (the disk each
 * sample stands for: show them as Point Gaussians scaled by Radius), "Element" (the input
 * cell), "Reference" (coordinates in that cell), "Curvature" and "Energy".
 *
 * The core's copy of the mesh is kept between updates while the input and its array are
 * unchanged, so moving Isovalue or Spacing re-samples without checking and linking the
 * cells again (NumberOfMeshBuilds counts the copies made).
 *
 * In an MPI run each process samples its own piece ("Element" numbers the cells of that
 * piece): the default Spacing follows the whole mesh's bounding box, a piece with no
 * cells gives no samples and no error, a failure on one rank empties every rank's output,
 * and "no surface" is warned only when no piece has a sample.
 */

#ifndef vtkIsobarFESamples_h
#define vtkIsobarFESamples_h

#include "IsobarVTKModule.h" // For export macro
#include "vtkPolyDataAlgorithm.h"

#include <string> // For members

struct IsobarFeMesh;
class vtkMultiProcessController;
class vtkUnstructuredGrid;

class ISOBARVTK_EXPORT vtkIsobarFESamples : public vtkPolyDataAlgorithm
{
public:
  static vtkIsobarFESamples* New();
  vtkTypeMacro(vtkIsobarFESamples, vtkPolyDataAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{
  /// The isovalue C (default 0).
  vtkSetMacro(Isovalue, double);
  vtkGetMacro(Isovalue, double);
  ///@}

  ///@{
  /// Distance between samples on flat parts, world units; 0 (default) picks 1/40 of the
  /// bounding-box diagonal.
  vtkSetMacro(Spacing, double);
  vtkGetMacro(Spacing, double);
  ///@}

  ///@{
  /// Curvature adaptivity ρ: extra density on curved parts (default 0: uniform).
  vtkSetMacro(CurvatureAdaptivity, double);
  vtkGetMacro(CurvatureAdaptivity, double);
  ///@}

  ///@{
  /// ε_T: every sample has |F - C| at most this (default 1e-6).
  vtkSetMacro(Tolerance, double);
  vtkGetMacro(Tolerance, double);
  ///@}

  ///@{
  /// Coarse-to-fine levels, each halving the spacing (default 2).
  vtkSetMacro(Levels, int);
  vtkGetMacro(Levels, int);
  ///@}

  ///@{
  /// Seed of the split/delete random bias (same seed, same samples).
  vtkSetMacro(Seed, int);
  vtkGetMacro(Seed, int);
  ///@}

  /// Copies of the input mesh handed to the core (once per input, not per isovalue).
  vtkGetMacro(NumberOfMeshBuilds, int);
  /// Forward evaluations of the last sampling (basis, mapping and field at a point).
  vtkGetMacro(LastEvaluations, double);
  /// Largest |F - C| over the last samples.
  vtkGetMacro(LastMaxResidual, double);
  /// The last update's errors, a line each (of each failing block of a multi-block input;
  /// "" when the update succeeded).
  const char* GetErrorMessage() const { return this->ErrorMessage.c_str(); }

  ///@{
  /// The processes that share the input's pieces (default: the global controller).
  virtual void SetController(vtkMultiProcessController*);
  vtkGetObjectMacro(Controller, vtkMultiProcessController);
  ///@}
  /// Called by the core's progress callback; true asks the core to stop.
  bool ReportProgress(double fraction, const char* phase);

protected:
  vtkIsobarFESamples();
  ~vtkIsobarFESamples() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

private:
  vtkIsobarFESamples(const vtkIsobarFESamples&) = delete;
  void operator=(const vtkIsobarFESamples&) = delete;

  void Fail(const std::string& message);
  /// The first setting outside its range, as a message naming it ("" when all are fine).
  std::string CheckSettings() const;
  /// Makes the core's copy of this rank's piece (kept while the input is unchanged) and
  /// names the array to contour in `field`; returns the failure ("" on success).
  std::string PrepareMesh(
    vtkUnstructuredGrid* input, vtkInformationVector** inputVector, std::string& field);
  /// Samples the core's mesh into `output`; returns the failure ("" on success,
  /// "cancelled") and the core's warnings in `warnings`.
  std::string SamplePiece(
    const std::string& field, double spacing, vtkPolyData* output, std::string& warnings);
  void FreeMesh();

  double Isovalue;
  double Spacing;
  double CurvatureAdaptivity;
  double Tolerance;
  int Levels;
  int Seed;
  int NumberOfMeshBuilds;
  double LastEvaluations;
  double LastMaxResidual;
  double LastProgress;
  std::string ErrorMessage;
  IsobarFeMesh* Mesh;
  vtkMultiProcessController* Controller;
  /// What the core's mesh was made from: the input's identity and MTime, the array.
  std::string BuiltFrom;
};

#endif
