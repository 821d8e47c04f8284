#include "vtkIsobarFESamples.h"

#include "vtkCellArray.h"
#include "vtkCellData.h"
#include "vtkCellType.h"
#include "vtkDataObject.h"
#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFloatArray.h"
#include "vtkGenericCell.h"
#include "vtkIdList.h"
#include "vtkIdTypeArray.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkPoints.h"
#include "vtkPolyData.h"
#include "vtkUnsignedCharArray.h"
#include "vtkUnstructuredGrid.h"

#include "IsobarBlock.h"
#include "IsobarLines.h"
#include "IsobarRanks.h"
#include "IsobarProgress.h"
#include "IsobarSettings.h"
#include "isobar.h"

#include <cmath>
#include <map>
#include <sstream>
#include <vector>

vtkStandardNewMacro(vtkIsobarFESamples);
vtkCxxSetObjectMacro(vtkIsobarFESamples, Controller, vtkMultiProcessController);

namespace
{
std::string CoreError(const char* call, IsobarStatus status)
{
  std::ostringstream msg;
  msg << call << " failed (status " << static_cast<int>(status)
      << "): " << isobar_last_error_message();
  return msg.str();
}

/// Owns core samples for the length of one update.
struct SamplesHandle
{
  IsobarSamples* Ptr = nullptr;
  ~SamplesHandle() { isobar_samples_free(this->Ptr); }
};

/// The grid as the core takes it: double points, VTK types, int64 offsets and
/// connectivity, HigherOrderDegrees when the input has them.
struct MeshArrays
{
  std::vector<double> Points;
  std::vector<uint8_t> Types;
  std::vector<int64_t> Offsets;
  std::vector<int64_t> Connectivity;
  std::vector<uint32_t> Degrees;
};

MeshArrays Collect(vtkUnstructuredGrid* input)
{
  MeshArrays m;
  const vtkIdType np = input->GetNumberOfPoints();
  const vtkIdType nc = input->GetNumberOfCells();
  m.Points.resize(3 * static_cast<size_t>(np));
  for (vtkIdType i = 0; i < np; ++i)
  {
    input->GetPoint(i, &m.Points[3 * static_cast<size_t>(i)]);
  }
  m.Types.reserve(static_cast<size_t>(nc));
  m.Offsets.reserve(static_cast<size_t>(nc) + 1);
  m.Offsets.push_back(0);
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < nc; ++c)
  {
    m.Types.push_back(static_cast<uint8_t>(input->GetCellType(c)));
    input->GetCellPoints(c, ids);
    for (vtkIdType k = 0; k < ids->GetNumberOfIds(); ++k)
    {
      m.Connectivity.push_back(static_cast<int64_t>(ids->GetId(k)));
    }
    m.Offsets.push_back(static_cast<int64_t>(m.Connectivity.size()));
  }
  // Readers do not always mark the array as the HigherOrderDegrees attribute (VTK 9.1's
  // XML reader does not): take it by its conventional name too.
  vtkDataArray* degrees = input->GetCellData()->GetHigherOrderDegrees();
  if (!degrees)
  {
    degrees = input->GetCellData()->GetArray("HigherOrderDegrees");
  }
  if (degrees && degrees->GetNumberOfComponents() == 3 && degrees->GetNumberOfTuples() == nc)
  {
    m.Degrees.resize(3 * static_cast<size_t>(nc));
    for (vtkIdType c = 0; c < nc; ++c)
    {
      for (int k = 0; k < 3; ++k)
      {
        m.Degrees[3 * static_cast<size_t>(c) + k] =
          static_cast<uint32_t>(degrees->GetComponent(c, k));
      }
    }
  }
  return m;
}

void AddDoubleArray(vtkPointData* pd, const char* name, int components, vtkIdType n,
  const double* data)
{
  vtkNew<vtkDoubleArray> a;
  a->SetName(name);
  a->SetNumberOfComponents(components);
  a->SetNumberOfTuples(n);
  if (n > 0)
  {
    std::copy_n(data, n * components, a->GetPointer(0));
  }
  pd->AddArray(a);
}
// The volume cells of `input`: the core leaves out the vertex, line and surface cells a
// mesher writes beside them, so a piece holding only those holds nothing to sample.
vtkIdType VolumeCells(vtkUnstructuredGrid* input)
{
  if (!input)
  {
    return 0;
  }
  std::map<int, int> dimension; // per cell type, from the first cell of that type
  vtkNew<vtkGenericCell> cell;
  vtkIdType volume = 0;
  for (vtkIdType c = 0; c < input->GetNumberOfCells(); ++c)
  {
    const int type = input->GetCellType(c);
    auto known = dimension.find(type);
    if (known == dimension.end())
    {
      input->GetCell(c, cell);
      known = dimension.emplace(type, cell->GetCellDimension()).first;
    }
    volume += known->second == 3 ? 1 : 0;
  }
  return volume;
}

} // namespace

/// The progress callback handed to the core.
struct vtkIsobarFESamplesProgress
{
  static int32_t Call(void* user, double fraction, const char* phase)
  {
    return static_cast<vtkIsobarFESamples*>(user)->ReportProgress(fraction, phase) ? 1 : 0;
  }
};

//------------------------------------------------------------------------------
vtkIsobarFESamples::vtkIsobarFESamples()
  : Isovalue(0.0)
  , Spacing(0.0)
  , CurvatureAdaptivity(0.0)
  , Tolerance(1e-6)
  , Levels(2)
  , Seed(1)
  , NumberOfMeshBuilds(0)
  , LastEvaluations(0.0)
  , LastMaxResidual(0.0)
  , LastProgress(-1.0)
  , Mesh(nullptr)
  , Controller(nullptr)
{
  this->SetController(vtkMultiProcessController::GetGlobalController());
  IsobarFeParams defaults;
  if (isobar_fe_params_default(&defaults) == ISOBAR_STATUS_OK)
  {
    this->Tolerance = defaults.tolerance;
    this->Levels = static_cast<int>(defaults.levels);
    this->Seed = static_cast<int>(defaults.seed);
  }
  this->SetInputArrayToProcess(
    0, 0, 0, vtkDataObject::FIELD_ASSOCIATION_POINTS, vtkDataSetAttributes::SCALARS);
}

//------------------------------------------------------------------------------
vtkIsobarFESamples::~vtkIsobarFESamples()
{
  this->FreeMesh();
  this->SetController(nullptr);
}

//------------------------------------------------------------------------------
void vtkIsobarFESamples::FreeMesh()
{
  isobar_fe_mesh_free(this->Mesh);
  this->Mesh = nullptr;
  this->BuiltFrom.clear();
}

//------------------------------------------------------------------------------
int vtkIsobarFESamples::FillInputPortInformation(int, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkUnstructuredGrid");
  return 1;
}

//------------------------------------------------------------------------------
void vtkIsobarFESamples::Fail(const std::string& message)
{
  const std::string line = IsobarAddError(this, this->ErrorMessage, message);
  vtkErrorMacro(<< line);
}

//------------------------------------------------------------------------------
bool vtkIsobarFESamples::ReportProgress(double fraction, const char* phase)
{
  return IsobarReportProgress(this, this->LastProgress, fraction, phase);
}

//------------------------------------------------------------------------------
int vtkIsobarFESamples::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkUnstructuredGrid* input = vtkUnstructuredGrid::GetData(inputVector[0], 0);
  vtkPolyData* output = vtkPolyData::GetData(outputVector, 0);
  IsobarBeginErrors(this, this->ErrorMessage);
  this->LastProgress = -1.0;
  output->Initialize();

  // Settings alone fail alike on every rank, before any collective call.
  const std::string badSetting = this->CheckSettings();
  if (!badSetting.empty())
  {
    this->Fail(badSetting);
    return 1;
  }

  // In an MPI run each rank samples its own piece, and every rank takes part in every
  // collective call below whatever happened to it, so that none waits for ever.
  vtkMultiProcessController* controller = this->Controller;
  const bool parallel = controller && controller->GetNumberOfProcesses() > 1;
  const vtkIdType cells = VolumeCells(input);
  vtkIdType allCells = cells;
  if (parallel)
  {
    controller->AllReduce(&cells, &allCells, 1, vtkCommunicator::SUM_OP);
  }
  std::string failure;
  std::string field;
  if (allCells == 0)
  {
    failure = "the input has no volume cells: give an unstructured grid of Lagrange, linear or quadratic volume cells";
  }
  else if (cells > 0)
  {
    failure = this->PrepareMesh(input, inputVector, field);
  }
  // else: other ranks hold the cells; this rank's piece and output are empty.

  double spacing = this->Spacing;
  if (parallel)
  {
    failure = IsobarAgreeOnFailure(controller, failure);
    if (failure.empty() && spacing <= 0.0)
    {
      // The default spacing follows the whole mesh's box, as in one process: from each
      // piece's own box the pieces would be sampled at different densities.
      double local[6] = { VTK_DOUBLE_MAX, VTK_DOUBLE_MAX, VTK_DOUBLE_MAX, VTK_DOUBLE_MAX,
        VTK_DOUBLE_MAX, VTK_DOUBLE_MAX };
      double box[6];
      if (cells > 0 && isobar_fe_mesh_bounds(this->Mesh, box) == ISOBAR_STATUS_OK)
      {
        for (int k = 0; k < 3; ++k)
        {
          local[k] = box[k];
          local[3 + k] = -box[3 + k];
        }
      }
      double whole[6];
      controller->AllReduce(local, whole, 6, vtkCommunicator::MIN_OP);
      // As the core computes it from one box: (hi - lo) per axis, then the length.
      const double dx = -whole[3] - whole[0], dy = -whole[4] - whole[1],
                   dz = -whole[5] - whole[2];
      spacing = std::sqrt(dx * dx + dy * dy + dz * dz) / 40.0;
    }
  }
  std::string warnings;
  if (failure.empty() && cells > 0)
  {
    failure = this->SamplePiece(field, spacing, output, warnings);
  }

  vtkIdType allSamples = output->GetNumberOfPoints();
  if (parallel)
  {
    const vtkIdType here = allSamples;
    controller->AllReduce(&here, &allSamples, 1, vtkCommunicator::SUM_OP);
    // All pieces or none: a rank that failed empties every rank's output.
    failure = IsobarAgreeOnFailure(controller, failure);
  }
  if (failure == "cancelled")
  {
    output->Initialize();
    this->ErrorMessage = failure;
    return 1;
  }
  if (!failure.empty())
  {
    output->Initialize();
    this->Fail(failure);
    return 1;
  }
  // Warnings, not errors: the samples are what was asked for, but perhaps not what was
  // meant (an isovalue the field never crosses). One vtkWarningMacro a line. In an MPI
  // run a piece without samples is no news when another piece has some.
  for (const std::string& line : IsobarLines(warnings.c_str()))
  {
    if (!(parallel && allSamples > 0 && IsobarNoSurfaceWarning(line)))
    {
      vtkWarningMacro(<< line);
    }
  }
  this->UpdateProgress(1.0);
  return 1;
}

//------------------------------------------------------------------------------
std::string vtkIsobarFESamples::CheckSettings() const
{
  return IsobarSettingsCheck()
    .AtLeast("Spacing", this->Spacing, 0.0, "0: 1/40 of the mesh's diagonal")
    .AtLeast("Curvature Adaptivity", this->CurvatureAdaptivity, 0.0, "0: uniform")
    .Inside("Tolerance", this->Tolerance, 0.0, 1.0)
    .Within("Levels", this->Levels, 0, 8)
    .Failure();
}

//------------------------------------------------------------------------------
std::string vtkIsobarFESamples::PrepareMesh(
  vtkUnstructuredGrid* input, vtkInformationVector** inputVector, std::string& field)
{
  vtkDataArray* values = this->GetInputArrayToProcess(0, inputVector);
  vtkInformation* chosen = this->GetInputArrayInformation(0);
  const char* wanted = chosen && chosen->Has(vtkDataObject::FIELD_NAME())
    ? chosen->Get(vtkDataObject::FIELD_NAME())
    : nullptr;
  if (!values || values->GetNumberOfTuples() != input->GetNumberOfPoints())
  {
    if (!wanted || !*wanted)
    {
      return "the input has no point scalars: choose a point array to contour";
    }
    return std::string("the input has no point array '") + wanted +
      (values ? "' (it is not point data)" : "'") + ": choose a point array to contour";
  }
  field = values->GetName() ? values->GetName() : "field";
  // One value a point: a vector would be read as its first component without a word.
  if (values->GetNumberOfComponents() != 1)
  {
    return "array '" + field + "' has " + std::to_string(values->GetNumberOfComponents()) +
      " components: choose a one-component point array (a Calculator can make a magnitude "
      "or pick a component)";
  }

  // The core's copy of the mesh, made again only when the points, the cells or the
  // array changed. The arrays themselves are the key, not the data set: ParaView touches
  // the data set's MTime on re-execution without changing what it holds.
  std::ostringstream key;
  auto identify = [&key](vtkObject* o) { key << o << "@" << (o ? o->GetMTime() : 0) << " "; };
  identify(input->GetPoints() ? input->GetPoints()->GetData() : nullptr);
  identify(input->GetCells());
  identify(input->GetCellTypesArray());
  identify(input->GetCellData()->GetArray("HigherOrderDegrees"));
  identify(values);
  key << field;
  if (!this->Mesh || key.str() != this->BuiltFrom)
  {
    this->FreeMesh();
    const MeshArrays m = Collect(input);
    IsobarStatus status = isobar_fe_mesh_create(m.Points.data(), m.Points.size() / 3,
      m.Types.data(), m.Types.size(), m.Offsets.data(), m.Connectivity.data(),
      m.Connectivity.size(), m.Degrees.empty() ? nullptr : m.Degrees.data(), &this->Mesh);
    if (status != ISOBAR_STATUS_OK)
    {
      this->Mesh = nullptr;
      return CoreError("isobar_fe_mesh_create", status);
    }
    const vtkIdType n = values->GetNumberOfTuples();
    std::vector<double> scalars(static_cast<size_t>(n));
    for (vtkIdType i = 0; i < n; ++i)
    {
      scalars[static_cast<size_t>(i)] = values->GetComponent(i, 0);
    }
    status = isobar_fe_mesh_add_array(
      this->Mesh, field.c_str(), scalars.data(), static_cast<size_t>(n), 1);
    if (status != ISOBAR_STATUS_OK)
    {
      this->FreeMesh();
      return CoreError("isobar_fe_mesh_add_array", status);
    }
    this->BuiltFrom = key.str();
    ++this->NumberOfMeshBuilds;
  }
  return std::string();
}

//------------------------------------------------------------------------------
std::string vtkIsobarFESamples::SamplePiece(
  const std::string& field, double spacing, vtkPolyData* output, std::string& warnings)
{
  // Sample.
  IsobarFeParams params;
  isobar_fe_params_default(&params);
  params.iso = this->Isovalue;
  params.spacing = spacing;
  params.rho = this->CurvatureAdaptivity;
  params.tolerance = this->Tolerance;
  params.levels = static_cast<uint32_t>(this->Levels);
  params.seed = static_cast<uint64_t>(this->Seed);
  SamplesHandle samples;
  this->UpdateProgress(0.0);
  const IsobarStatus status = isobar_fe_sample(this->Mesh, field.c_str(), &params,
    &vtkIsobarFESamplesProgress::Call, this, &samples.Ptr);
  if (status == ISOBAR_STATUS_CANCELLED)
  {
    return "cancelled";
  }
  if (status != ISOBAR_STATUS_OK)
  {
    return CoreError("isobar_fe_sample", status);
  }
  IsobarFeStats stats;
  stats.struct_size = sizeof(stats);
  if (isobar_samples_stats(samples.Ptr, &stats) == ISOBAR_STATUS_OK)
  {
    this->LastEvaluations = static_cast<double>(stats.evaluations);
    this->LastMaxResidual = stats.max_residual;
  }

  // Vertices with Normals, Radius and the per-sample arrays.
  const vtkIdType n = static_cast<vtkIdType>(isobar_samples_count(samples.Ptr));
  vtkNew<vtkDoubleArray> xyz;
  xyz->SetNumberOfComponents(3);
  xyz->SetNumberOfTuples(n);
  vtkNew<vtkFloatArray> normals;
  normals->SetName("Normals");
  normals->SetNumberOfComponents(3);
  normals->SetNumberOfTuples(n);
  if (n > 0)
  {
    std::copy_n(isobar_samples_positions(samples.Ptr), 3 * n, xyz->GetPointer(0));
    std::copy_n(isobar_samples_normals(samples.Ptr), 3 * n, normals->GetPointer(0));
  }
  vtkNew<vtkPoints> points;
  points->SetData(xyz);
  vtkNew<vtkIdTypeArray> offsets;
  vtkNew<vtkIdTypeArray> connectivity;
  offsets->SetNumberOfValues(n + 1);
  connectivity->SetNumberOfValues(n);
  for (vtkIdType i = 0; i <= n; ++i)
  {
    offsets->SetValue(i, i);
  }
  for (vtkIdType i = 0; i < n; ++i)
  {
    connectivity->SetValue(i, i);
  }
  vtkNew<vtkCellArray> verts;
  verts->SetData(offsets, connectivity);
  output->SetPoints(points);
  output->SetVerts(verts);
  vtkPointData* pd = output->GetPointData();
  pd->SetNormals(normals);
  AddDoubleArray(pd, "Radius", 1, n, isobar_samples_radii(samples.Ptr));
  const size_t na = isobar_samples_attribute_count(samples.Ptr);
  for (size_t i = 0; i < na; ++i)
  {
    const char* name = nullptr;
    size_t components = 0;
    const double* data = nullptr;
    const IsobarStatus got =
      isobar_samples_attribute(samples.Ptr, i, &name, &components, &data);
    if (got != ISOBAR_STATUS_OK)
    {
      return CoreError("isobar_samples_attribute", got);
    }
    AddDoubleArray(pd, name, static_cast<int>(components), n, data);
  }
  const char* text = isobar_samples_warnings(samples.Ptr);
  warnings = text ? text : "";
  return std::string();
}

//------------------------------------------------------------------------------
void vtkIsobarFESamples::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "Isovalue: " << this->Isovalue << "\n";
  os << indent << "Spacing: " << this->Spacing << "\n";
  os << indent << "CurvatureAdaptivity: " << this->CurvatureAdaptivity << "\n";
  os << indent << "Tolerance: " << this->Tolerance << "\n";
  os << indent << "Levels: " << this->Levels << "\n";
  os << indent << "Seed: " << this->Seed << "\n";
  os << indent << "NumberOfMeshBuilds: " << this->NumberOfMeshBuilds << "\n";
  os << indent << "Controller: " << this->Controller << "\n";
}
