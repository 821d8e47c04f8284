#include "vtkIsobarVolumeSlider.h"

#include "vtkCellArray.h"
#include "vtkDataArray.h"
#include "vtkFloatArray.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMatrix3x3.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkPoints.h"
#include "vtkPolyData.h"

#include "IsobarBlock.h"
#include "IsobarProgress.h"
#include "IsobarSettings.h"
#include "isobar.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <vector>

#include <unistd.h>

vtkStandardNewMacro(vtkIsobarVolumeSlider);

namespace
{
/// A store path no other filter (in this or another process) uses.
std::string NewStorePath()
{
  static std::atomic<unsigned> counter{ 0 };
  std::ostringstream name;
  name << "isobar-slider-" << ::getpid() << "-" << counter++ << ".isoslider";
  return (std::filesystem::temp_directory_path() / name.str()).string();
}

std::string CoreError(const char* call, IsobarStatus status)
{
  std::ostringstream msg;
  msg << call << " failed (status " << static_cast<int>(status)
      << "): " << isobar_last_error_message();
  return msg.str();
}
} // namespace

//------------------------------------------------------------------------------
vtkIsobarVolumeSlider::vtkIsobarVolumeSlider()
  : Isovalue(0.0)
  , LodErrorBound(0.0)
  , LodMaxLevel(0)
  , MemoryBudget(4.0)
  , NumberOfStoreBuilds(0)
  , NumberOfUpdates(0)
  , LastUpdateSeconds(0.0)
  , Slider(nullptr)
  , AtIsovalue(false)
  , AppliedIsovalue(0.0)
  , LastProgress(-1.0)
{
  this->SetInputArrayToProcess(
    0, 0, 0, vtkDataObject::FIELD_ASSOCIATION_POINTS, vtkDataSetAttributes::SCALARS);
}

//------------------------------------------------------------------------------
vtkIsobarVolumeSlider::~vtkIsobarVolumeSlider()
{
  this->CloseStore();
}

//------------------------------------------------------------------------------
void vtkIsobarVolumeSlider::CloseStore()
{
  isobar_slider_free(this->Slider);
  this->Slider = nullptr;
  this->AtIsovalue = false;
  if (!this->StorePath.empty())
  {
    std::error_code ignored;
    std::filesystem::remove(this->StorePath, ignored);
    this->StorePath.clear();
  }
  this->BuiltFrom.clear();
}

//------------------------------------------------------------------------------
int vtkIsobarVolumeSlider::FillInputPortInformation(int, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageData");
  return 1;
}

//------------------------------------------------------------------------------
void vtkIsobarVolumeSlider::Fail(const std::string& message)
{
  const std::string line = IsobarAddError(this, this->ErrorMessage, message);
  vtkErrorMacro(<< line);
}

/// The progress callback handed to the core's store build.
struct vtkIsobarVolumeSliderProgress
{
  static int32_t Call(void* user, double fraction, const char* phase)
  {
    return static_cast<vtkIsobarVolumeSlider*>(user)->ReportProgress(fraction, phase) ? 1 : 0;
  }
};

//------------------------------------------------------------------------------
bool vtkIsobarVolumeSlider::ReportProgress(double fraction, const char* phase)
{
  return IsobarReportProgress(this, this->LastProgress, fraction, phase);
}

//------------------------------------------------------------------------------
int vtkIsobarVolumeSlider::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkImageData* input = vtkImageData::GetData(inputVector[0], 0);
  vtkPolyData* output = vtkPolyData::GetData(outputVector, 0);
  IsobarBeginErrors(this, this->ErrorMessage);
  output->Initialize();

  vtkDataArray* values = this->GetInputArrayToProcess(0, inputVector);
  if (!values)
  {
    this->Fail("the input image has no point scalars: choose a point array");
    return 1;
  }
  int dims[3];
  input->GetDimensions(dims);
  double origin[3], spacing[3];
  input->GetSpacing(spacing);
  if (dims[0] < 2 || dims[1] < 2 || dims[2] < 2)
  {
    this->Fail("the input image must have at least 2 points along each axis");
    return 1;
  }
  if (!input->GetDirectionMatrix()->IsIdentity())
  {
    this->Fail("the input image has a direction matrix (rotated axes): not supported");
    return 1;
  }
  // The core reads one value a point: a cell array (one fewer along each axis) or a
  // vector would be read past its end or as the wrong values.
  const char* name = values->GetName() ? values->GetName() : "(unnamed)";
  int association = vtkDataObject::FIELD_ASSOCIATION_POINTS;
  this->GetInputArrayToProcess(0, inputVector, association);
  if (association != vtkDataObject::FIELD_ASSOCIATION_POINTS ||
    values->GetNumberOfTuples() != input->GetNumberOfPoints())
  {
    std::ostringstream msg;
    msg << "array '" << name << "' is not point data (" << values->GetNumberOfTuples()
        << " values for " << input->GetNumberOfPoints() << " points): choose a point array";
    this->Fail(msg.str());
    return 1;
  }
  if (values->GetNumberOfComponents() != 1)
  {
    std::ostringstream msg;
    msg << "array '" << name << "' has " << values->GetNumberOfComponents()
        << " components: choose a one-component point array (a Calculator can make a "
           "magnitude or pick a component)";
    this->Fail(msg.str());
    return 1;
  }
  // The first point, not the image origin: an extent need not start at index 0
  // (ParaView's Wavelet spans -10..10), and the core's lattice starts at its first node.
  input->GetPoint(0, origin);

  // The core checks the rest (a bound below 1, at most 6 levels) in isobar_slider_set_lod.
  const std::string badSetting = IsobarSettingsCheck()
                                   .AtLeast("Lod Error Bound", this->LodErrorBound, 0.0,
                                     "0: the exact surface")
                                   .AtLeast("Lod Max Level", this->LodMaxLevel, 0,
                                     "0: the core's default")
                                   .AtLeast("Memory Budget", this->MemoryBudget, 0.0,
                                     "GiB, 0: the core's default")
                                   .Failure();
  if (!badSetting.empty())
  {
    this->Fail(badSetting);
    return 1;
  }

  // 1. Pre-encode the volume, unless the open store was built from this very data.
  std::ostringstream key;
  key.precision(17);
  key << values << " " << values->GetMTime() << " " << (values->GetName() ? values->GetName() : "")
      << " " << dims[0] << " " << dims[1] << " " << dims[2];
  for (int a = 0; a < 3; ++a)
  {
    key << " " << origin[a] << " " << spacing[a];
  }
  if (!this->Slider || key.str() != this->BuiltFrom)
  {
    this->CloseStore();
    const vtkIdType n = values->GetNumberOfTuples();
    const size_t sizes[3] = { static_cast<size_t>(dims[0]), static_cast<size_t>(dims[1]),
      static_cast<size_t>(dims[2]) };
    const std::string path = NewStorePath();
    // 0 (the core's default) stays 0.
    const uint64_t budget =
      static_cast<uint64_t>(std::min(this->MemoryBudget, 1.0e9) * 1024.0 * 1024.0 * 1024.0);
    // The store holds float32. Types it holds exactly go as float; wider ones (double,
    // 32- and 64-bit integers) as double, which the core narrows, refusing values beyond
    // float's range and warning where float steps are coarse for the value range (a
    // pressure of 101325 ± 0.02 Pa): a cast here would move the surface without a word.
    const int type = values->GetDataType();
    const bool exact = type == VTK_FLOAT || vtkDataArray::GetDataTypeSize(type) <= 2;
    IsobarStatus status;
    const char* call;
    this->LastProgress = -1.0;
    this->UpdateProgress(0.0);
    if (exact)
    {
      std::vector<float> scalars(static_cast<size_t>(n));
      for (vtkIdType i = 0; i < n; ++i)
      {
        scalars[static_cast<size_t>(i)] = static_cast<float>(values->GetComponent(i, 0));
      }
      call = "isobar_slider_build_f32";
      status = isobar_slider_build_f32(scalars.data(), sizes, origin, spacing, path.c_str(), 0.0,
        0, budget, &vtkIsobarVolumeSliderProgress::Call, this);
    }
    else
    {
      std::vector<double> scalars(static_cast<size_t>(n));
      for (vtkIdType i = 0; i < n; ++i)
      {
        scalars[static_cast<size_t>(i)] = values->GetComponent(i, 0);
      }
      call = "isobar_slider_build_f64";
      status = isobar_slider_build_f64(scalars.data(), sizes, origin, spacing, path.c_str(), 0.0,
        0, budget, &vtkIsobarVolumeSliderProgress::Call, this);
    }
    if (status == ISOBAR_STATUS_CANCELLED)
    {
      // Aborted (the core left no store): empty output; the next update builds again.
      output->Initialize();
      this->ErrorMessage = "cancelled";
      vtkDebugMacro(<< "Store build cancelled: empty output");
      return 1;
    }
    if (status != ISOBAR_STATUS_OK)
    {
      std::ostringstream msg;
      msg << "array '" << name << "': " << CoreError(call, status);
      this->Fail(msg.str());
      return 1;
    }
    std::istringstream warnings(isobar_last_warnings());
    for (std::string line; std::getline(warnings, line);)
    {
      vtkWarningMacro(<< "array '" << name << "': " << line);
    }
    this->StorePath = path;
    status = isobar_slider_open(path.c_str(), &this->Slider);
    if (status != ISOBAR_STATUS_OK)
    {
      this->Fail(CoreError("isobar_slider_open", status));
      this->CloseStore();
      return 1;
    }
    this->BuiltFrom = key.str();
    ++this->NumberOfStoreBuilds;
  }

  // 2. Slide to the isovalue: the slider applies only the change since the last one.
  //    A re-run for another reason (a new level of detail) does not slide again.
  if (!this->AtIsovalue || this->AppliedIsovalue != this->Isovalue)
  {
    this->AtIsovalue = false;
    IsobarSliderChange change;
    const IsobarStatus status =
      isobar_slider_set_isovalue(this->Slider, this->Isovalue, nullptr, nullptr, &change);
    if (status != ISOBAR_STATUS_OK)
    {
      this->Fail(CoreError("isobar_slider_set_isovalue", status));
      return 1;
    }
    this->AtIsovalue = true;
    this->AppliedIsovalue = this->Isovalue;
    ++this->NumberOfUpdates;
    this->LastUpdateSeconds = change.seconds;
  }
  // An empty output says why, as the SPH and FE filters' do.
  double lo = 0.0;
  double hi = 0.0;
  if (isobar_slider_triangle_count(this->Slider) == 0 &&
    isobar_slider_value_range(this->Slider, &lo, &hi) == ISOBAR_STATUS_OK &&
    !(lo < this->Isovalue && this->Isovalue < hi))
  {
    vtkWarningMacro(<< "no surface at isovalue " << this->Isovalue << ": array '" << name
                    << "' ranges over " << lo << ".." << hi);
  }

  // 3. The surface's arrays: the slider's exact ones, or its level of detail (computed
  //    by the core on the first read after an isovalue or LOD change).
  size_t nv = 0;
  size_t nt = 0;
  const float* xyzIn = nullptr;
  const float* normalsIn = nullptr;
  const uint32_t* tris = nullptr;
  if (this->LodErrorBound > 0.0)
  {
    IsobarStatus status = isobar_slider_set_lod(
      this->Slider, this->LodErrorBound, static_cast<uint32_t>(this->LodMaxLevel));
    if (status != ISOBAR_STATUS_OK)
    {
      this->Fail(CoreError("isobar_slider_set_lod", status));
      return 1;
    }
    status = isobar_slider_lod_mesh(this->Slider, &nv, &nt, &xyzIn, &normalsIn, &tris);
    if (status != ISOBAR_STATUS_OK)
    {
      this->Fail(CoreError("isobar_slider_lod_mesh", status));
      return 1;
    }
  }
  else
  {
    nv = isobar_slider_vertex_count(this->Slider);
    nt = isobar_slider_triangle_count(this->Slider);
    xyzIn = isobar_slider_positions(this->Slider);
    normalsIn = isobar_slider_normals(this->Slider);
    tris = isobar_slider_triangles(this->Slider);
  }

  // 4. Into the output.
  vtkNew<vtkFloatArray> xyz;
  xyz->SetNumberOfComponents(3);
  xyz->SetNumberOfTuples(static_cast<vtkIdType>(nv));
  vtkNew<vtkFloatArray> normals;
  normals->SetName("Normals");
  normals->SetNumberOfComponents(3);
  normals->SetNumberOfTuples(static_cast<vtkIdType>(nv));
  if (nv > 0)
  {
    std::copy_n(xyzIn, 3 * nv, xyz->GetPointer(0));
    std::copy_n(normalsIn, 3 * nv, normals->GetPointer(0));
  }
  vtkNew<vtkPoints> points;
  points->SetData(xyz);
  vtkNew<vtkCellArray> polys;
  polys->AllocateExact(static_cast<vtkIdType>(nt), static_cast<vtkIdType>(3 * nt));
  for (size_t t = 0; t < nt; ++t)
  {
    const vtkIdType ids[3] = { tris[3 * t], tris[3 * t + 1], tris[3 * t + 2] };
    polys->InsertNextCell(3, ids);
  }
  output->SetPoints(points);
  output->SetPolys(polys);
  output->GetPointData()->SetNormals(normals);
  return 1;
}

//------------------------------------------------------------------------------
void vtkIsobarVolumeSlider::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "Isovalue: " << this->Isovalue << "\n";
  os << indent << "LodErrorBound: " << this->LodErrorBound << "\n";
  os << indent << "LodMaxLevel: " << this->LodMaxLevel << "\n";
  os << indent << "MemoryBudget: " << this->MemoryBudget << "\n";
  os << indent << "NumberOfStoreBuilds: " << this->NumberOfStoreBuilds << "\n";
  os << indent << "NumberOfUpdates: " << this->NumberOfUpdates << "\n";
}
