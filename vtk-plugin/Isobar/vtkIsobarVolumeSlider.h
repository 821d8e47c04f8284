/**
 * @class   vtkIsobarVolumeSlider
 * @brief   isovalue sliding on image data (isobar's ISOSLIDER)
 *
 * The input is a vtkImageData with a point scalar array (the one chosen with
 * SetInputArrayToProcess(0, ...), else the active scalars; component 0 of a vector).
 * The first update pre-encodes the volume into an isobar store (a temporary file, removed
 * with the filter); later updates that only change Isovalue reuse the open slider, which
 * applies just the change since the last isovalue: the triangles of cells that stop or
 * start crossing and the moved vertices. The output is the marching-cubes surface of the
 * trilinear volume (float points, "Normals" from the volume's gradient).
 *
 * LodErrorBound > 0 asks for the core's level of detail of that surface instead (the
 * paper's section 2.2): blocks of cells merge where the coarser trilinear interpolant stays
 * within LodErrorBound x (value range) of every sample it replaces and the topology is
 * kept; the mesh stays closed where merged cells meet finer ones, and every vertex lies
 * on the exact surface. 0 (the default) shows the exact surface. Changing LodErrorBound or
 * LodMaxLevel re-runs only the level of detail: no new store, no isovalue change.
 *
 * A new input array, new values or new geometry rebuild the store. NumberOfStoreBuilds
 * and NumberOfUpdates count the work done, so that scripts (and tests) can tell a slide
 * from a start-over.
 */

#ifndef vtkIsobarVolumeSlider_h
#define vtkIsobarVolumeSlider_h

#include "IsobarVTKModule.h" // For export macro
#include "vtkPolyDataAlgorithm.h"

#include <string> // For members

struct IsobarSlider;

class ISOBARVTK_EXPORT vtkIsobarVolumeSlider : public vtkPolyDataAlgorithm
{
public:
  static vtkIsobarVolumeSlider* New();
  vtkTypeMacro(vtkIsobarVolumeSlider, vtkPolyDataAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{
  /// The isovalue shown (default 0).
  vtkSetMacro(Isovalue, double);
  vtkGetMacro(Isovalue, double);
  ///@}

  ///@{
  /// Level of detail: the largest difference allowed between a sample that a merged cell
  /// drops and that cell's trilinear interpolant, as a fraction of the volume's value
  /// range, in [0, 1). 0 (default): the exact surface. 0.001 is the paper's bound.
  vtkSetMacro(LodErrorBound, double);
  vtkGetMacro(LodErrorBound, double);
  ///@}

  ///@{
  /// Most merge levels of the level of detail (a level-L cell spans 2^L cells per axis),
  /// at most 6; 0 (default) takes the core's default, 3. Used when LodErrorBound > 0.
  vtkSetMacro(LodMaxLevel, int);
  vtkGetMacro(LodMaxLevel, int);
  ///@}

  ///@{
  /// GiB the pre-encoding may hold besides the volume (default 4; 0: the core's
  /// default). Past about 29 bytes a node the core sorts the values on disk, beside the
  /// store, and writes the same store; too small a budget even for that is an error.
  /// Changing it does not rebuild a store already built.
  vtkSetMacro(MemoryBudget, double);
  vtkGetMacro(MemoryBudget, double);
  ///@}

  /// Times the volume was pre-encoded (once per input volume).
  vtkGetMacro(NumberOfStoreBuilds, int);
  /// Isovalue changes applied by the slider.
  vtkGetMacro(NumberOfUpdates, int);
  /// Core time of the last isovalue change, in seconds.
  vtkGetMacro(LastUpdateSeconds, double);
  /// The last update's errors, a line each (of each failing block of a multi-block input;
  /// "" when the update succeeded).
  const char* GetErrorMessage() const { return this->ErrorMessage.c_str(); }

protected:
  vtkIsobarVolumeSlider();
  ~vtkIsobarVolumeSlider() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

private:
  vtkIsobarVolumeSlider(const vtkIsobarVolumeSlider&) = delete;
  void operator=(const vtkIsobarVolumeSlider&) = delete;

  void Fail(const std::string& message);
  void CloseStore();

public:
  /// The core's progress during the store build (the long step: seconds for a 256³
  /// volume): reported to VTK's progress, and `false` stops it when AbortExecute is set.
  bool ReportProgress(double fraction, const char* phase);

private:
  double LastProgress;

  double Isovalue;
  double LodErrorBound;
  int LodMaxLevel;
  double MemoryBudget;
  int NumberOfStoreBuilds;
  int NumberOfUpdates;
  double LastUpdateSeconds;
  std::string ErrorMessage;
  IsobarSlider* Slider;
  /// Whether the open slider stands at Isovalue already (a LOD change needs no slide).
  bool AtIsovalue;
  double AppliedIsovalue;
  std::string StorePath;
  /// What the open store was built from: array identity, its MTime, the geometry.
  std::string BuiltFrom;
};

#endif
