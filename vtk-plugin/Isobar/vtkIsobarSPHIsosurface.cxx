#include "vtkIsobarSPHIsosurface.h"

#include "vtkCellArray.h"
#include "vtkCommand.h"
#include "vtkCommunicator.h"
#include "vtkDataArray.h"
#include "vtkDataArraySelection.h"
#include "vtkDataObject.h"
#include "vtkDataSetAttributes.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkIdTypeArray.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMultiProcessController.h"
#include "vtkObjectFactory.h"
#include "vtkPartitionedDataSet.h"
#include "vtkPointData.h"
#include "vtkPointSet.h"
#include "vtkPoints.h"
#include "vtkPolyData.h"
#include "vtkSmartPointer.h"
#include "vtkStringArray.h"
#include "vtkUnsignedCharArray.h"

#include "IsobarBlock.h"
#include "IsobarLines.h"
#include "IsobarRanks.h"
#include "IsobarProgress.h"
#include "IsobarSettings.h"
#include "isobar.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <sstream>

vtkStandardNewMacro(vtkIsobarSPHIsosurface);
vtkCxxSetObjectMacro(vtkIsobarSPHIsosurface, Controller, vtkMultiProcessController);

namespace
{
/// Smoothing-length arrays looked for when neither a constant nor an array is given
/// (the isobar CLI's rule).
const char* const AutoSmoothingLengthArrays[] = { "h", "smoothing_length", "hsml" };

/// A particle array the extraction asks for.
struct Request
{
  std::string Name;
  bool Required;
};

/// A particle array as doubles, item-major; Components < 0: absent.
struct ParticleArray
{
  std::string Name;
  int Components = -1;
  std::vector<double> Data;
};

/// Particles (ghost points removed) with the requested arrays, in request order.
struct ParticleBuffers
{
  vtkIdType Count = 0;
  std::vector<double> Positions;
  std::vector<ParticleArray> Arrays;

  const ParticleArray* Find(const std::string& name) const
  {
    for (const auto& a : this->Arrays)
    {
      if (a.Name == name && a.Components > 0)
      {
        return &a;
      }
    }
    return nullptr;
  }
};

/// Owns an IsobarParticles handle.
struct ParticlesHandle
{
  IsobarParticles* Ptr = nullptr;
  ~ParticlesHandle() { isobar_particles_free(this->Ptr); }
};

/// Owns an IsobarSurface handle.
struct SurfaceHandle
{
  IsobarSurface* Ptr = nullptr;
  ~SurfaceHandle() { isobar_surface_free(this->Ptr); }
};

bool NonEmpty(const char* s)
{
  return s != nullptr && s[0] != '\0';
}

std::string PointArrayNames(vtkPointData* pd)
{
  std::string names;
  for (int i = 0; i < pd->GetNumberOfArrays(); ++i)
  {
    const char* name = pd->GetArrayName(i);
    if (name)
    {
      names += (names.empty() ? "" : ", ") + std::string(name);
    }
  }
  return names.empty() ? "none" : names;
}

/// Copies `source` (tuples of any numeric type) as doubles, keeping tuples whose `keep`
/// flag is set (all when `keep` is empty).
void CopyAsDoubles(vtkDataArray* source, const std::vector<char>& keep, std::vector<double>& out)
{
  vtkNew<vtkDoubleArray> asDouble;
  const double* data = nullptr;
  if (auto* d = vtkDoubleArray::SafeDownCast(source))
  {
    data = d->GetPointer(0);
  }
  else
  {
    asDouble->DeepCopy(source);
    data = asDouble->GetPointer(0);
  }
  const int nc = source->GetNumberOfComponents();
  const vtkIdType n = source->GetNumberOfTuples();
  if (keep.empty())
  {
    out.assign(data, data + n * nc);
    return;
  }
  out.clear();
  for (vtkIdType i = 0; i < n; ++i)
  {
    if (keep[i])
    {
      out.insert(out.end(), data + i * nc, data + (i + 1) * nc);
    }
  }
}

/// The particles of one point set (NULL: none) and their requested arrays, ghost points
/// skipped. Returns an error message or "".
std::string CollectPiece(
  vtkPointSet* input, const std::vector<Request>& requests, ParticleBuffers& out)
{
  out = ParticleBuffers();
  const vtkIdType n = input ? input->GetNumberOfPoints() : 0;
  std::vector<char> keep;
  vtkIdType kept = n;
  if (n > 0)
  {
    if (vtkUnsignedCharArray* ghosts = input->GetPointGhostArray())
    {
      keep.resize(n);
      kept = 0;
      const unsigned char skip =
        vtkDataSetAttributes::DUPLICATEPOINT | vtkDataSetAttributes::HIDDENPOINT;
      for (vtkIdType i = 0; i < n; ++i)
      {
        keep[i] = (ghosts->GetValue(i) & skip) == 0;
        kept += keep[i];
      }
    }
  }
  out.Count = kept;
  out.Arrays.resize(requests.size());
  for (size_t k = 0; k < requests.size(); ++k)
  {
    out.Arrays[k].Name = requests[k].Name;
  }
  if (kept == 0)
  {
    return std::string();
  }
  CopyAsDoubles(input->GetPoints()->GetData(), keep, out.Positions);
  vtkPointData* pd = input->GetPointData();
  for (size_t k = 0; k < requests.size(); ++k)
  {
    const Request& r = requests[k];
    vtkDataArray* a = pd->GetArray(r.Name.c_str());
    if (!a)
    {
      if (pd->GetAbstractArray(r.Name.c_str()))
      {
        return "point array '" + r.Name + "' is not numeric";
      }
      if (r.Required)
      {
        return "the input has no point array '" + r.Name +
          "' (point arrays: " + PointArrayNames(pd) + ")";
      }
      continue;
    }
    out.Arrays[k].Components = a->GetNumberOfComponents();
    CopyAsDoubles(a, keep, out.Arrays[k].Data);
  }
  return std::string();
}

/// This rank's particles: those of `pieces` (one point set, or the partitions of a
/// vtkPartitionedDataSet, which is one dataset cut into pieces: its particles are one
/// fluid, and a surface per partition would have walls at the cuts), concatenated.
std::string CollectLocal(
  const std::vector<vtkPointSet*>& pieces, const std::vector<Request>& requests,
  ParticleBuffers& out)
{
  out = ParticleBuffers();
  std::string error = CollectPiece(nullptr, requests, out);
  for (size_t p = 0; p < pieces.size() && error.empty(); ++p)
  {
    ParticleBuffers piece;
    error = CollectPiece(pieces[p], requests, piece);
    if (!error.empty() && pieces.size() > 1)
    {
      error = "partition " + std::to_string(p) + ": " + error;
    }
    if (!error.empty() || piece.Count == 0)
    {
      continue;
    }
    const bool first = out.Count == 0;
    for (size_t k = 0; k < requests.size() && error.empty(); ++k)
    {
      const ParticleArray& a = piece.Arrays[k];
      ParticleArray& into = out.Arrays[k];
      if (!first && a.Components != into.Components)
      {
        auto count = [](int components) {
          return components <= 0 ? std::string("none")
                                 : std::to_string(components) +
              (components == 1 ? " component" : " components");
        };
        error = "point array '" + a.Name + "' has " + count(a.Components) + " in partition " +
          std::to_string(p) + " but " + count(into.Components) + " in the partitions before it";
      }
      into.Components = a.Components;
      into.Data.insert(into.Data.end(), a.Data.begin(), a.Data.end());
    }
    out.Count += piece.Count;
    out.Positions.insert(out.Positions.end(), piece.Positions.begin(), piece.Positions.end());
  }
  return error;
}

/// A message naming this rank's first particle with a non-finite position, or "".
std::string NonFinitePosition(const ParticleBuffers& particles, int rank)
{
  for (vtkIdType i = 0; i < particles.Count; ++i)
  {
    const double* p = &particles.Positions[3 * i];
    if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2])))
    {
      std::ostringstream msg;
      msg << "particle " << i << " of rank " << rank << " (ghost points skipped) has a "
          << "non-finite position (" << p[0] << ", " << p[1] << ", " << p[2] << ")";
      return msg.str();
    }
  }
  return std::string();
}

/// Makes every rank agree on the particle arrays (all ranks must call it). Afterwards each
/// array of `local` has the components every rank with particles has (-1: absent
/// everywhere), also on ranks without particles; `total` is the particle count over all
/// ranks. Returns an error message, "" on every rank or non-empty on every rank.
std::string AgreeOnArrays(vtkMultiProcessController* controller, const std::string& localError,
  const std::vector<Request>& requests, ParticleBuffers& local, long long& total)
{
  const int nproc = controller->GetNumberOfProcesses();
  const size_t k = requests.size();
  // Header: error flag, particle count, components of each requested array.
  const size_t hlen = 2 + k;
  std::vector<long long> header(hlen, 0);
  header[0] = localError.empty() ? 0 : 1;
  header[1] = localError.empty() ? local.Count : 0;
  for (size_t a = 0; a < k; ++a)
  {
    header[2 + a] = local.Arrays[a].Components;
  }
  std::vector<long long> headers(hlen * nproc);
  controller->AllGather(header.data(), headers.data(), static_cast<vtkIdType>(hlen));
  if (!localError.empty())
  {
    return localError;
  }
  total = 0;
  for (int p = 0; p < nproc; ++p)
  {
    if (headers[p * hlen] != 0)
    {
      std::ostringstream msg;
      msg << "rank " << p << " could not use its particles (see its error message)";
      return msg.str();
    }
    total += headers[p * hlen + 1];
  }
  for (size_t a = 0; a < k; ++a)
  {
    int components = -1;
    for (int p = 0; p < nproc; ++p)
    {
      const long long* h = &headers[p * hlen];
      if (h[1] > 0 && h[2 + a] > 0)
      {
        components = static_cast<int>(h[2 + a]);
        break;
      }
    }
    for (int p = 0; p < nproc; ++p)
    {
      const long long* h = &headers[p * hlen];
      if (h[1] > 0 && h[2 + a] != components)
      {
        std::ostringstream msg;
        msg << "point array '" << requests[a].Name << "' has " << h[2 + a]
            << " components on rank " << p << " but " << components
            << " elsewhere (-1: absent)";
        return msg.str();
      }
    }
    local.Arrays[a].Components = components;
  }
  return std::string();
}

/// Smallest and largest smoothing length of `particles` (constant `h` when `hArray` is
/// empty); `bad` counts values that are not positive and finite.
void SmoothingLengthRange(const ParticleBuffers& particles, const std::string& hArray, double h,
  double& minH, double& maxH, double& bad)
{
  minH = std::numeric_limits<double>::infinity();
  maxH = 0.0;
  bad = 0.0;
  if (particles.Count == 0)
  {
    return;
  }
  const ParticleArray* a = hArray.empty() ? nullptr : particles.Find(hArray);
  if (!a)
  {
    minH = maxH = h;
    bad = (h > 0.0 && std::isfinite(h)) ? 0.0 : 1.0;
    return;
  }
  for (vtkIdType i = 0; i < particles.Count; ++i)
  {
    const double v = a->Data[i * a->Components];
    if (!(v > 0.0 && std::isfinite(v)))
    {
      bad += 1.0;
      continue;
    }
    minH = std::min(minH, v);
    maxH = std::max(maxH, v);
  }
}

/// Triangles of `output` per isovalue: all of them for one isovalue; for several, by the
/// "Isovalue" array at each triangle's first point, which holds its isovalue exactly.
std::vector<vtkIdType> TrianglesPerIsovalue(vtkPolyData* output, const std::vector<double>& isovalues)
{
  std::vector<vtkIdType> counts(isovalues.size(), 0);
  vtkDataArray* tags = output->GetPointData()->GetArray("Isovalue");
  if (isovalues.empty())
  {
    return counts;
  }
  if (isovalues.size() == 1 || !tags)
  {
    counts[0] = output->GetNumberOfCells();
    return counts;
  }
  vtkCellArray* polys = output->GetPolys();
  vtkIdType n = 0;
  const vtkIdType* ids = nullptr;
  for (polys->InitTraversal(); polys->GetNextCell(n, ids);)
  {
    const auto at = std::find(isovalues.begin(), isovalues.end(), tags->GetTuple1(ids[0]));
    if (at != isovalues.end())
    {
      ++counts[at - isovalues.begin()];
    }
  }
  return counts;
}

/// Cut positions along `axis` splitting the particles of all ranks into `nproc` slabs of
/// about equal particle counts (a global histogram of 64 bins per rank, at least 4096,
/// cuts on bin edges). Returns nproc + 1 values, the first -inf and the last +inf.
std::vector<double> EqualCountCuts(vtkMultiProcessController* controller,
  const ParticleBuffers& particles, int axis, double lo, double hi, long long total)
{
  const int nproc = controller->GetNumberOfProcesses();
  const int bins = std::max(4096, 64 * nproc);
  const double width = hi - lo;
  std::vector<long long> local(bins, 0), global(bins, 0);
  if (width > 0.0)
  {
    for (vtkIdType i = 0; i < particles.Count; ++i)
    {
      const double t = (particles.Positions[3 * i + axis] - lo) / width * bins;
      const int b = std::min(bins - 1, std::max(0, static_cast<int>(t)));
      ++local[b];
    }
  }
  controller->AllReduce(local.data(), global.data(), bins, vtkCommunicator::SUM_OP);
  std::vector<double> cuts(nproc + 1);
  cuts.front() = -std::numeric_limits<double>::infinity();
  cuts.back() = std::numeric_limits<double>::infinity();
  long long below = 0;
  int b = 0;
  for (int r = 1; r < nproc; ++r)
  {
    // The first bin edge with at least r/nproc of the particles below it.
    const long double target = static_cast<long double>(total) * r / nproc;
    while (b < bins && below + global[b] <= target)
    {
      below += global[b];
      ++b;
    }
    // Edge b (below it: `below` particles, <= target) or b + 1, whichever is nearer.
    int edge = b;
    if (b < bins && target - below > below + global[b] - target)
    {
      edge = b + 1;
    }
    cuts[r] = width > 0.0 ? lo + width * edge / bins : lo;
    cuts[r] = std::max(cuts[r], cuts[r - 1]);
  }
  return cuts;
}

/// Sends every rank the particles within its slab [cuts[r] - halo, cuts[r + 1] + halo]
/// along `axis` (all ranks must call it, with the same cuts and halo). Returns this rank's
/// particles: its slab plus the halo, from every rank, in rank order.
ParticleBuffers Redistribute(vtkMultiProcessController* controller, const ParticleBuffers& local,
  int axis, const std::vector<double>& cuts, double halo)
{
  const int nproc = controller->GetNumberOfProcesses();
  const int rank = controller->GetLocalProcessId();
  // One row per particle: position, then the components of each present array.
  size_t row = 3;
  for (const auto& a : local.Arrays)
  {
    row += a.Components > 0 ? static_cast<size_t>(a.Components) : 0;
  }
  auto wanted = [&](int dest, vtkIdType i) {
    const double x = local.Positions[3 * i + axis];
    return x >= cuts[dest] - halo && x <= cuts[dest + 1] + halo;
  };
  std::vector<long long> counts(nproc, 0), allCounts(static_cast<size_t>(nproc) * nproc, 0);
  for (int dest = 0; dest < nproc; ++dest)
  {
    for (vtkIdType i = 0; i < local.Count; ++i)
    {
      counts[dest] += wanted(dest, i) ? 1 : 0;
    }
  }
  controller->AllGather(counts.data(), allCounts.data(), nproc);

  ParticleBuffers mine;
  mine.Arrays.resize(local.Arrays.size());
  for (size_t a = 0; a < local.Arrays.size(); ++a)
  {
    mine.Arrays[a].Name = local.Arrays[a].Name;
    mine.Arrays[a].Components = local.Arrays[a].Components;
  }
  std::vector<double> rows;
  for (int dest = 0; dest < nproc; ++dest)
  {
    // What this rank sends to `dest`, packed row by row.
    std::vector<double> send;
    send.reserve(static_cast<size_t>(counts[dest]) * row);
    for (vtkIdType i = 0; i < local.Count; ++i)
    {
      if (!wanted(dest, i))
      {
        continue;
      }
      send.insert(send.end(), &local.Positions[3 * i], &local.Positions[3 * i] + 3);
      for (const auto& a : local.Arrays)
      {
        if (a.Components > 0)
        {
          const double* v = &a.Data[static_cast<size_t>(i) * a.Components];
          send.insert(send.end(), v, v + a.Components);
        }
      }
    }
    std::vector<vtkIdType> lengths(nproc, 0), offsets(nproc, 0);
    vtkIdType received = 0;
    for (int p = 0; p < nproc; ++p)
    {
      lengths[p] = static_cast<vtkIdType>(allCounts[static_cast<size_t>(p) * nproc + dest] * row);
      offsets[p] = received;
      received += lengths[p];
    }
    if (dest == rank)
    {
      rows.assign(std::max<vtkIdType>(received, 1), 0.0);
    }
    double dummy = 0.0;
    controller->GatherV(send.empty() ? &dummy : send.data(), dest == rank ? rows.data() : &dummy,
      static_cast<vtkIdType>(send.size()), lengths.data(), offsets.data(), dest);
    if (dest == rank)
    {
      mine.Count = static_cast<vtkIdType>(received / static_cast<vtkIdType>(row));
    }
  }
  // Unpack the rows into positions and arrays.
  mine.Positions.resize(3 * static_cast<size_t>(mine.Count));
  for (auto& a : mine.Arrays)
  {
    if (a.Components > 0)
    {
      a.Data.resize(static_cast<size_t>(mine.Count) * a.Components);
    }
  }
  for (vtkIdType i = 0; i < mine.Count; ++i)
  {
    const double* src = &rows[static_cast<size_t>(i) * row];
    std::copy_n(src, 3, &mine.Positions[3 * i]);
    src += 3;
    for (auto& a : mine.Arrays)
    {
      if (a.Components > 0)
      {
        std::copy_n(src, a.Components, &a.Data[static_cast<size_t>(i) * a.Components]);
        src += a.Components;
      }
    }
  }
  return mine;
}

std::string CoreError(const char* what, IsobarStatus status)
{
  std::ostringstream msg;
  msg << what << " failed (status " << static_cast<int>(status)
      << "): " << isobar_last_error_message();
  return msg.str();
}

/// The core's particle set from the buffers. Returns an error message or "".
std::string MakeParticles(const ParticleBuffers& particles, ParticlesHandle& handle)
{
  IsobarStatus status = isobar_particles_create(
    particles.Positions.data(), static_cast<size_t>(particles.Count), &handle.Ptr);
  if (status != ISOBAR_STATUS_OK)
  {
    return CoreError("isobar_particles_create", status);
  }
  for (const auto& a : particles.Arrays)
  {
    if (a.Components <= 0)
    {
      continue;
    }
    status = isobar_particles_add_array(handle.Ptr, a.Name.c_str(), a.Data.data(),
      static_cast<size_t>(particles.Count), static_cast<size_t>(a.Components));
    if (status != ISOBAR_STATUS_OK)
    {
      return CoreError(("isobar_particles_add_array('" + a.Name + "')").c_str(), status);
    }
  }
  return std::string();
}

/// Surface -> vtkPolyData: double points, triangles, Normals, per-vertex double arrays.
/// Returns an error message or "".
std::string SurfaceToPolyData(const IsobarSurface* surface, vtkPolyData* output)
{
  const vtkIdType nv = static_cast<vtkIdType>(isobar_surface_vertex_count(surface));
  const vtkIdType nt = static_cast<vtkIdType>(isobar_surface_triangle_count(surface));
  vtkNew<vtkDoubleArray> xyz;
  xyz->SetNumberOfComponents(3);
  xyz->SetNumberOfTuples(nv);
  if (nv > 0)
  {
    std::copy_n(isobar_surface_positions(surface), 3 * nv, xyz->GetPointer(0));
  }
  vtkNew<vtkPoints> points;
  points->SetData(xyz);
  output->SetPoints(points);

  vtkNew<vtkIdTypeArray> offsets;
  vtkNew<vtkIdTypeArray> connectivity;
  offsets->SetNumberOfValues(nt + 1);
  connectivity->SetNumberOfValues(3 * nt);
  const uint32_t* tris = isobar_surface_triangles(surface);
  for (vtkIdType t = 0; t <= nt; ++t)
  {
    offsets->SetValue(t, 3 * t);
  }
  for (vtkIdType i = 0; i < 3 * nt; ++i)
  {
    connectivity->SetValue(i, static_cast<vtkIdType>(tris[i]));
  }
  vtkNew<vtkCellArray> polys;
  polys->SetData(offsets, connectivity);
  output->SetPolys(polys);

  vtkPointData* pd = output->GetPointData();
  if (const float* normals = isobar_surface_normals(surface))
  {
    vtkNew<vtkFloatArray> n;
    n->SetName("Normals");
    n->SetNumberOfComponents(3);
    n->SetNumberOfTuples(nv);
    std::copy_n(normals, 3 * nv, n->GetPointer(0));
    pd->SetNormals(n);
  }
  const size_t na = isobar_surface_attribute_count(surface);
  for (size_t i = 0; i < na; ++i)
  {
    const char* name = nullptr;
    size_t components = 0;
    const double* data = nullptr;
    IsobarStatus status = isobar_surface_attribute(surface, i, &name, &components, &data);
    if (status != ISOBAR_STATUS_OK)
    {
      output->Initialize();
      return CoreError("isobar_surface_attribute", status);
    }
    vtkNew<vtkDoubleArray> a;
    a->SetName(name);
    a->SetNumberOfComponents(static_cast<int>(components));
    a->SetNumberOfTuples(nv);
    if (nv > 0 && components > 0)
    {
      std::copy_n(data, nv * static_cast<vtkIdType>(components), a->GetPointer(0));
    }
    pd->AddArray(a);
  }
  return std::string();
}
} // anonymous namespace

/// The progress callback handed to the core.
struct vtkIsobarSPHIsosurfaceProgress
{
  static int32_t Call(void* user, double fraction, const char* phase)
  {
    auto* self = static_cast<vtkIsobarSPHIsosurface*>(user);
    return self->ReportProgress(fraction, phase) ? 1 : 0;
  }
};

//------------------------------------------------------------------------------
vtkIsobarSPHIsosurface::vtkIsobarSPHIsosurface()
{
  // Defaults come from the core, so every host starts from the same parameters.
  IsobarSphParams defaults;
  std::memset(&defaults, 0, sizeof(defaults));
  isobar_sph_params_default(&defaults);

  this->FieldMode = SUM_OF_WEIGHTS;
  this->FieldComponent = -1;
  this->Isovalues.assign(1, 0.6);
  this->SmoothingLength = 0.0;
  this->SmoothingLengthArrayName = nullptr;
  this->HScale = defaults.h_scale;
  this->VolumeArrayName = nullptr;
  this->DensityArrayName = nullptr;
  this->MassArrayName = nullptr;
  this->Mass = defaults.mass;
  this->Shepard = defaults.shepard != 0;
  this->Kernel = static_cast<int>(defaults.kernel);
  this->GridFactor = defaults.grid_factor;
  this->Method = MARCHING_CORRECTORS;
  IsobarAdaptiveParams adaptive;
  std::memset(&adaptive, 0, sizeof(adaptive));
  isobar_adaptive_params_default(&adaptive);
  this->SplashThreshold = static_cast<int>(adaptive.splash_threshold);
  this->MaxError = adaptive.max_error;
  this->BisectionIterations = static_cast<int>(adaptive.bisection_iterations);
  this->Backend = static_cast<int>(adaptive.backend);
  this->Correct = defaults.correct != 0;
  this->Tolerance = defaults.tolerance;
  this->Trim = defaults.trim != 0;
  this->TrimNode = defaults.trim_node;
  this->TrimVertex = defaults.trim_vertex;
  this->ComputeNormals = defaults.normals != 0;
  this->MemoryBudget = static_cast<double>(defaults.memory_budget) / (1024.0 * 1024.0 * 1024.0);
  this->FullGrid = defaults.full_grid != 0;
  this->FixedLattice = defaults.fixed_lattice != 0;
  std::copy_n(defaults.lattice_origin, 3, this->LatticeOrigin);
  this->LatticeCellSize = defaults.lattice_cell_size;
  this->PieceAxis = -1;
  this->PieceBounds[0] = this->PieceBounds[1] = 0.0;
  this->PieceParticles = 0;
  this->CarriedArraySelection = vtkDataArraySelection::New();
  this->Controller = nullptr;
  this->SetController(vtkMultiProcessController::GetGlobalController());
  this->LastProgress = -1.0;

  this->SetInputArrayToProcess(
    0, 0, 0, vtkDataObject::FIELD_ASSOCIATION_POINTS, vtkDataSetAttributes::SCALARS);
}

//------------------------------------------------------------------------------
vtkIsobarSPHIsosurface::~vtkIsobarSPHIsosurface()
{
  this->SetSmoothingLengthArrayName(nullptr);
  this->SetVolumeArrayName(nullptr);
  this->SetDensityArrayName(nullptr);
  this->SetMassArrayName(nullptr);
  this->CarriedArraySelection->Delete();
  this->SetController(nullptr);
}

//------------------------------------------------------------------------------
void vtkIsobarSPHIsosurface::SetNumberOfIsovalues(int count)
{
  count = std::max(count, 0);
  if (static_cast<size_t>(count) != this->Isovalues.size())
  {
    this->Isovalues.resize(count, 0.0);
    this->Modified();
  }
}

int vtkIsobarSPHIsosurface::GetNumberOfIsovalues()
{
  return static_cast<int>(this->Isovalues.size());
}

void vtkIsobarSPHIsosurface::SetIsovalue(int index, double value)
{
  if (index < 0)
  {
    return;
  }
  if (static_cast<size_t>(index) >= this->Isovalues.size())
  {
    this->Isovalues.resize(index + 1, 0.0);
  }
  else if (this->Isovalues[index] == value)
  {
    return;
  }
  this->Isovalues[index] = value;
  this->Modified();
}

double vtkIsobarSPHIsosurface::GetIsovalue(int index)
{
  return index >= 0 && static_cast<size_t>(index) < this->Isovalues.size()
    ? this->Isovalues[index]
    : 0.0;
}

//------------------------------------------------------------------------------
vtkMTimeType vtkIsobarSPHIsosurface::GetMTime()
{
  return std::max(this->Superclass::GetMTime(), this->CarriedArraySelection->GetMTime());
}

//------------------------------------------------------------------------------
std::string vtkIsobarSPHIsosurface::FieldString(const char* arrayName, int components) const
{
  if (this->FieldMode == SUM_OF_WEIGHTS || !NonEmpty(arrayName))
  {
    return "SumOfWeights";
  }
  std::string field(arrayName);
  if (components > 1)
  {
    field += this->FieldComponent < 0 ? std::string(":mag")
                                      : ":" + std::to_string(this->FieldComponent);
  }
  return field;
}

//------------------------------------------------------------------------------
int vtkIsobarSPHIsosurface::FillInputPortInformation(int, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkPointSet");
  // Whole, not partition by partition (see CollectLocal).
  info->Append(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkPartitionedDataSet");
  return 1;
}

//------------------------------------------------------------------------------
void vtkIsobarSPHIsosurface::Fail(const std::string& message)
{
  const std::string line = IsobarAddError(this, this->ErrorMessage, message);
  vtkErrorMacro(<< line);
}

//------------------------------------------------------------------------------
bool vtkIsobarSPHIsosurface::ReportProgress(double fraction, const char* phase)
{
  return IsobarReportProgress(this, this->LastProgress, fraction, phase);
}

//------------------------------------------------------------------------------
std::vector<std::string> vtkIsobarSPHIsosurface::CarriedArrayNames()
{
  std::vector<std::string> names;
  for (int i = 0; i < this->CarriedArraySelection->GetNumberOfArrays(); ++i)
  {
    const char* name = this->CarriedArraySelection->GetArrayName(i);
    if (name && this->CarriedArraySelection->ArrayIsEnabled(name))
    {
      names.emplace_back(name);
    }
  }
  return names;
}

//------------------------------------------------------------------------------
std::string vtkIsobarSPHIsosurface::FieldArrayName()
{
  vtkInformation* info = this->GetInputArrayInformation(0);
  if (this->FieldMode == POINT_ARRAY && info && info->Has(vtkDataObject::FIELD_NAME()))
  {
    return info->Get(vtkDataObject::FIELD_NAME());
  }
  return std::string();
}

//------------------------------------------------------------------------------
int vtkIsobarSPHIsosurface::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkDataObject* input = vtkDataObject::GetData(inputVector[0], 0);
  vtkPolyData* output = vtkPolyData::GetData(outputVector, 0);
  output->Initialize();
  IsobarBeginErrors(this, this->ErrorMessage);
  this->LastProgress = -1.0;
  this->PieceAxis = -1;
  this->PieceBounds[0] = this->PieceBounds[1] = 0.0;
  this->PieceParticles = 0;

  const std::string badSetting = this->CheckSettings();
  if (!badSetting.empty())
  {
    this->Fail(badSetting);
    return 1;
  }

  // 1. The particle arrays to collect, in an order every rank shares. Errors found from
  // the settings alone happen alike on every rank, so no rank skips a collective call.
  const std::string fieldArray = this->FieldArrayName();
  if (this->FieldMode == POINT_ARRAY && fieldArray.empty())
  {
    this->Fail("Field Mode is 'Point array' but no input array is selected");
    return 1;
  }
  const bool adaptive = this->Method == ADAPTIVE;
  if (adaptive && this->Controller && this->Controller->GetNumberOfProcesses() > 1)
  {
    // Every rank sees the same Method, so every rank returns here alike.
    this->Fail("Method 'Adaptive' runs in one process (its grids are not split into "
               "pieces yet); choose 'Marching Correctors' for parallel runs");
    return 1;
  }
  if (adaptive && this->Isovalues.size() != 1)
  {
    this->Fail("Method 'Adaptive' extracts one isovalue at a time, got " +
      std::to_string(this->Isovalues.size()));
    return 1;
  }
  const bool hFromArray = NonEmpty(this->SmoothingLengthArrayName);
  const bool hAuto = !hFromArray && this->SmoothingLength <= 0.0;
  const std::vector<std::string> carried = this->CarriedArrayNames();
  if (adaptive && this->FullGrid)
  {
    vtkWarningMacro(<< "Full Grid applies to 'Marching Correctors'; 'Adaptive' ignores it");
  }
  std::vector<Request> requests;
  if (!fieldArray.empty())
  {
    requests.push_back({ fieldArray, true });
  }
  if (hFromArray)
  {
    requests.push_back({ this->SmoothingLengthArrayName, true });
  }
  for (const char* name : AutoSmoothingLengthArrays)
  {
    if (hAuto)
    {
      requests.push_back({ name, false });
    }
  }
  for (const char* name : { this->VolumeArrayName, this->DensityArrayName, this->MassArrayName })
  {
    if (NonEmpty(name))
    {
      requests.push_back({ name, true });
    }
  }
  for (const auto& name : carried)
  {
    requests.push_back({ name, true });
  }

  // 2. This rank's particles. In a parallel run every rank takes part in every collective
  // call below; errors are agreed on first, so that all ranks return at the same point.
  ParticleBuffers particles;
  std::vector<vtkPointSet*> pieces;
  std::string error;
  if (auto* partitioned = vtkPartitionedDataSet::SafeDownCast(input))
  {
    for (unsigned int p = 0; p < partitioned->GetNumberOfPartitions() && error.empty(); ++p)
    {
      vtkDataObject* partition = partitioned->GetPartitionAsDataObject(p);
      if (partition && !vtkPointSet::SafeDownCast(partition))
      {
        error = "partition " + std::to_string(p) + " is a " + partition->GetClassName() +
          ", not a point set of particles";
      }
      pieces.push_back(vtkPointSet::SafeDownCast(partition));
    }
  }
  else
  {
    pieces.push_back(vtkPointSet::SafeDownCast(input));
  }
  if (error.empty())
  {
    error = CollectLocal(pieces, requests, particles);
  }
  vtkMultiProcessController* controller = this->Controller;
  const bool parallel = controller && controller->GetNumberOfProcesses() > 1;
  const int nproc = parallel ? controller->GetNumberOfProcesses() : 1;
  const int rank = parallel ? controller->GetLocalProcessId() : 0;
  long long total = particles.Count;
  if (parallel)
  {
    if (error.empty())
    {
      // Partitioning sorts particles by position: a NaN would silently go nowhere.
      error = NonFinitePosition(particles, rank);
    }
    error = AgreeOnArrays(controller, error, requests, particles, total);
  }
  if (!error.empty())
  {
    this->Fail(error);
    return 1;
  }
  if (total == 0)
  {
    // An emitter before its first particle: an empty surface, not an error, but said
    // (once, by rank 0), as an isovalue the field never crosses is.
    if (rank == 0)
    {
      vtkWarningMacro(<< "no particles: empty output");
    }
    return 1;
  }

  // 3. What the data decides: the smoothing-length array, the field string. In a
  // parallel run the arrays' components were agreed on, so every rank decides alike.
  std::string hArray = hFromArray ? std::string(this->SmoothingLengthArrayName) : std::string();
  for (const char* name : AutoSmoothingLengthArrays)
  {
    if (hAuto && hArray.empty() && particles.Find(name))
    {
      hArray = name;
    }
  }
  if (hAuto && hArray.empty())
  {
    this->Fail("no smoothing length: set Smoothing Length (a constant h > 0) or Smoothing "
               "Length Array (the input has no 'h', 'smoothing_length' or 'hsml' array)");
    return 1;
  }
  const int fieldComponents = fieldArray.empty() ? 1 : particles.Find(fieldArray)->Components;
  if (fieldComponents > 1 && this->FieldComponent >= fieldComponents)
  {
    std::ostringstream msg;
    msg << "Field Component " << this->FieldComponent << " does not exist: '" << fieldArray
        << "' has " << fieldComponents << " components (-1 = magnitude)";
    this->Fail(msg.str());
    return 1;
  }
  const std::string field = this->FieldString(fieldArray.c_str(), fieldComponents);
  std::vector<const char*> carriedNames;
  for (const auto& name : carried)
  {
    carriedNames.push_back(name.c_str());
  }
  IsobarSphParams params = this->MakeParams(field, hArray, carriedNames);

  // 4. The virtual grid. Single process: the data's own grid (as the CLI) unless Fixed
  // Lattice is on. Parallel: a lattice all ranks share, by default the one a single
  // process would use on all particles (first node at the global minimum corner minus
  // the largest support and one cell, cells of Grid Factor x the global smallest h), so
  // the pieces together are the single-process surface.
  bool extract = true;
  if (parallel || this->FixedLattice)
  {
    if (!hArray.empty() && particles.Find(hArray)->Components != 1)
    {
      this->Fail("smoothing length array '" + hArray + "' must have one component");
      return 1;
    }
    double minH, maxH, bad;
    SmoothingLengthRange(particles, hArray, this->SmoothingLength, minH, maxH, bad);
    // MIN over ranks of: bounds (max as -max), smallest h, -largest h, -bad count.
    double mins[9] = { std::numeric_limits<double>::infinity(),
      std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
      std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
      std::numeric_limits<double>::infinity(), minH, -maxH, -bad };
    for (vtkIdType i = 0; i < particles.Count; ++i)
    {
      for (int a = 0; a < 3; ++a)
      {
        const double x = particles.Positions[3 * i + a];
        mins[a] = std::min(mins[a], x);
        mins[3 + a] = std::min(mins[3 + a], -x);
      }
    }
    if (parallel)
    {
      double local[9];
      std::copy_n(mins, 9, local);
      controller->AllReduce(local, mins, 9, vtkCommunicator::MIN_OP);
    }
    const double lo[3] = { mins[0], mins[1], mins[2] };
    const double hi[3] = { -mins[3], -mins[4], -mins[5] };
    minH = mins[6];
    maxH = -mins[7];
    if (mins[8] < 0.0)
    {
      std::ostringstream msg;
      msg << "smoothing lengths must be positive and finite: " << -mins[8]
          << " particle(s) have one that is not";
      this->Fail(msg.str());
      return 1;
    }
    if (!(this->HScale > 0.0))
    {
      this->Fail("H Scale must be positive");
      return 1;
    }
    const double cell =
      this->LatticeCellSize > 0.0 ? this->LatticeCellSize : this->GridFactor * minH;
    if (!(cell > 0.0 && std::isfinite(cell)))
    {
      std::ostringstream msg;
      msg << "the virtual cell size must be positive and finite, got " << cell
          << " (Lattice Cell Size, or Grid Factor x smallest h)";
      this->Fail(msg.str());
      return 1;
    }
    // As the core: supports from the scaled h, the grid from the unscaled h.
    const double supportFactor = this->Kernel == QUINTIC ? 3.0 : 2.0;
    const double maxSupport = maxH * this->HScale * supportFactor;
    params.fixed_lattice = 1;
    params.lattice_cell_size = cell;
    for (int a = 0; a < 3; ++a)
    {
      params.lattice_origin[a] =
        this->FixedLattice ? this->LatticeOrigin[a] : lo[a] - (maxSupport + cell);
    }

    if (parallel)
    {
      // One slab per rank along the longest axis, about equal particle counts; each rank
      // gets its slab's particles plus a halo of two supports and one cell (the computed
      // volumes of the particles that shape the field need their own neighbours) and
      // keeps the surface of the cells whose lowest corner lies in its slab.
      int axis = 0;
      for (int a = 1; a < 3; ++a)
      {
        if (hi[a] - lo[a] > hi[axis] - lo[axis])
        {
          axis = a;
        }
      }
      const std::vector<double> cuts =
        EqualCountCuts(controller, particles, axis, lo[axis], hi[axis], total);
      const double halo = 2.0 * maxSupport + cell;
      particles = Redistribute(controller, particles, axis, cuts, halo);
      const double huge = std::numeric_limits<double>::max();
      params.clip = 1;
      for (int a = 0; a < 3; ++a)
      {
        params.clip_min[a] = -huge;
        params.clip_max[a] = huge;
      }
      if (rank > 0)
      {
        params.clip_min[axis] = cuts[rank];
      }
      if (rank < nproc - 1)
      {
        params.clip_max[axis] = cuts[rank + 1];
      }
      this->PieceAxis = axis;
      this->PieceBounds[0] = params.clip_min[axis];
      this->PieceBounds[1] = params.clip_max[axis];
      this->PieceParticles = particles.Count;
      // An empty slab (all particles on one side of a cut) or no particles near it:
      // nothing to extract here.
      extract = particles.Count > 0 && params.clip_min[axis] < params.clip_max[axis];
    }
  }

  // 5. The core does the rest.
  std::string failure; // this rank's error ("cancelled" for an abort)
  std::string warnings; // the core's, one a line, shown once the ranks agree
  SurfaceHandle surface;
  if (extract)
  {
    ParticlesHandle handle;
    failure = MakeParticles(particles, handle);
    particles = ParticleBuffers(); // the particle set owns copies now
    if (failure.empty())
    {
      this->UpdateProgress(0.0);
      IsobarStatus status;
      const char* call;
      if (this->Method == ADAPTIVE)
      {
        IsobarAdaptiveParams adaptive;
        std::memset(&adaptive, 0, sizeof(adaptive));
        isobar_adaptive_params_default(&adaptive);
        adaptive.splash_threshold = static_cast<uint32_t>(this->SplashThreshold);
        adaptive.max_error = this->MaxError;
        adaptive.bisection_iterations = static_cast<uint32_t>(this->BisectionIterations);
        adaptive.backend = static_cast<uint32_t>(this->Backend);
        call = "isobar_adaptive_extract";
        status = isobar_adaptive_extract(handle.Ptr, &params, &adaptive,
          &vtkIsobarSPHIsosurfaceProgress::Call, this, &surface.Ptr, nullptr);
      }
      else
      {
        call = "isobar_sph_extract";
        status = isobar_sph_extract(
          handle.Ptr, &params, &vtkIsobarSPHIsosurfaceProgress::Call, this, &surface.Ptr);
      }
      if (status == ISOBAR_STATUS_CANCELLED)
      {
        failure = "cancelled";
      }
      else if (status != ISOBAR_STATUS_OK)
      {
        failure = CoreError(call, status);
      }
    }
    if (failure.empty())
    {
      warnings = isobar_surface_warnings(surface.Ptr);
      failure = SurfaceToPolyData(surface.Ptr, output);
    }
    if (failure.empty() && this->Backend == ISOBAR_BACKEND_AUTO)
    {
      failure = this->NoteAutoBackend(output);
    }
  }
  std::vector<vtkIdType> crossed; // triangles per isovalue over all ranks
  if (parallel)
  {
    // Each rank extracts its slab: its "no surface at isovalue" is news about the whole
    // only for an isovalue no rank has a triangle of.
    const std::vector<vtkIdType> local = TrianglesPerIsovalue(output, this->Isovalues);
    crossed.assign(local.size(), 0);
    if (!local.empty()) // the same isovalues on every rank: all call, or none
    {
      controller->AllReduce(local.data(), crossed.data(), static_cast<vtkIdType>(local.size()),
        vtkCommunicator::SUM_OP);
    }
    // All pieces or none: a rank that failed empties every rank's output.
    failure = IsobarAgreeOnFailure(controller, failure);
  }
  if (failure == "cancelled")
  {
    output->Initialize();
    this->ErrorMessage = failure;
    vtkDebugMacro(<< "Extraction cancelled: empty output");
    return 1;
  }
  if (!failure.empty())
  {
    output->Initialize();
    this->Fail(failure);
    return 1;
  }
  // Warnings, not errors: the surface is what was asked for, but perhaps not what was
  // meant (an isovalue the field never crosses, h in other units than the positions).
  this->Warn(warnings, crossed);
  this->UpdateProgress(1.0);
  return 1;
}

//------------------------------------------------------------------------------
void vtkIsobarSPHIsosurface::Warn(
  const std::string& warnings, const std::vector<vtkIdType>& crossed)
{
  for (const std::string& line : IsobarLines(warnings.c_str()))
  {
    double iso = 0.0;
    if (!crossed.empty() && IsobarNoSurfaceWarning(line, &iso))
    {
      const auto at = std::find(this->Isovalues.begin(), this->Isovalues.end(), iso);
      if (at != this->Isovalues.end() && crossed[at - this->Isovalues.begin()] > 0)
      {
        continue; // another rank's slab has this surface
      }
    }
    vtkWarningMacro(<< line);
  }
}

//------------------------------------------------------------------------------
std::string vtkIsobarSPHIsosurface::NoteAutoBackend(vtkPolyData* output)
{
  const char* note = nullptr;
  const IsobarStatus status = isobar_auto_backend_note(&note);
  if (status != ISOBAR_STATUS_OK)
  {
    return CoreError("isobar_auto_backend_note", status);
  }
  if (note == nullptr || note[0] == '\0')
  {
    return ""; // Auto ran on a GPU
  }
  // A warning, not an error: the surface is right, only slower than the user may expect.
  // ParaView lists it in Output Messages; the CLI prints the same line on stderr.
  vtkWarningMacro(<< "backend auto: running on the CPU (" << note << ")");
  vtkNew<vtkStringArray> array;
  array->SetName("IsobarBackendNote");
  array->InsertNextValue(note);
  output->GetFieldData()->AddArray(array);
  return "";
}

//------------------------------------------------------------------------------
std::string vtkIsobarSPHIsosurface::CheckSettings() const
{
  IsobarSettingsCheck check;
  check.AtLeast("Field Component", this->FieldComponent, -1, "-1: the magnitude")
    .AtLeast("Smoothing Length", this->SmoothingLength, 0.0,
      "0: from the Smoothing Length Array or the data")
    .Above("H Scale", this->HScale, 0.0)
    .AtLeast("Mass", this->Mass, 0.0, "0: none")
    .Above("Grid Factor", this->GridFactor, 0.0)
    .AtLeast("Splash Threshold", this->SplashThreshold, 0, "0: no splash rule")
    .AtLeast("Max Error", this->MaxError, 0.0, "0: no error criterion")
    .Within("Bisection Iterations", this->BisectionIterations, 0, 16)
    .Inside("Tolerance", this->Tolerance, 0.0, 1.0)
    .AtLeast("Trim Node", this->TrimNode, 0.0)
    .AtLeast("Trim Vertex", this->TrimVertex, 0.0)
    .Above("Memory Budget", this->MemoryBudget, 0.0, "GiB")
    .AtLeast("Lattice Cell Size", this->LatticeCellSize, 0.0,
      "0: Grid Factor x the smallest smoothing length");
  return check.Failure();
}

//------------------------------------------------------------------------------
IsobarSphParams vtkIsobarSPHIsosurface::MakeParams(const std::string& field,
  const std::string& hArray, const std::vector<const char*>& carried) const
{
  IsobarSphParams params;
  std::memset(&params, 0, sizeof(params));
  isobar_sph_params_default(&params);
  params.kernel = static_cast<uint32_t>(this->Kernel);
  params.h = this->SmoothingLength;
  params.h_array = hArray.empty() ? nullptr : hArray.c_str();
  params.h_scale = this->HScale;
  params.field = field.c_str();
  params.volume_array = NonEmpty(this->VolumeArrayName) ? this->VolumeArrayName : nullptr;
  params.density_array = NonEmpty(this->DensityArrayName) ? this->DensityArrayName : nullptr;
  params.mass_array = NonEmpty(this->MassArrayName) ? this->MassArrayName : nullptr;
  params.mass = this->Mass;
  params.shepard = this->Shepard ? 1 : 0;
  params.correct = this->Correct ? 1 : 0;
  params.isovalues = this->Isovalues.data();
  params.isovalue_count = this->Isovalues.size();
  params.grid_factor = this->GridFactor;
  params.tolerance = this->Tolerance;
  // As the CLI: a free surface is never trimmed against its own field.
  params.trim = (this->Trim && this->FieldMode != SUM_OF_WEIGHTS) ? 1 : 0;
  params.trim_node = this->TrimNode;
  params.trim_vertex = this->TrimVertex;
  params.normals = this->ComputeNormals ? 1 : 0;
  params.attributes = carried.empty() ? nullptr : carried.data();
  params.attribute_count = carried.size();
  params.memory_budget =
    static_cast<uint64_t>(std::min(this->MemoryBudget, 1.0e9) * 1024.0 * 1024.0 * 1024.0);
  params.full_grid = this->FullGrid ? 1 : 0;
  params.backend = static_cast<uint32_t>(this->Backend);
  return params;
}

//------------------------------------------------------------------------------
void vtkIsobarSPHIsosurface::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  // One "Name: value" line per ParaView property (same names), full precision: the
  // ParaView tests read the settings back from here.
  auto str = [](const char* s) { return s ? s : ""; };
  const auto precision = os.precision(17);
  std::string inputArray;
  if (vtkInformation* info = this->GetInputArrayInformation(0))
  {
    if (info->Has(vtkDataObject::FIELD_NAME()))
    {
      inputArray = info->Get(vtkDataObject::FIELD_NAME());
    }
  }
  os << indent << "FieldMode: " << this->FieldMode << "\n";
  os << indent << "InputArray: " << inputArray << "\n";
  os << indent << "FieldComponent: " << this->FieldComponent << "\n";
  os << indent << "Isovalues:";
  for (double v : this->Isovalues)
  {
    os << " " << v;
  }
  os << "\n";
  os << indent << "SmoothingLength: " << this->SmoothingLength << "\n";
  os << indent << "SmoothingLengthArray: " << str(this->SmoothingLengthArrayName) << "\n";
  os << indent << "HScale: " << this->HScale << "\n";
  os << indent << "Kernel: " << this->Kernel << "\n";
  os << indent << "VolumeArray: " << str(this->VolumeArrayName) << "\n";
  os << indent << "DensityArray: " << str(this->DensityArrayName) << "\n";
  os << indent << "MassArray: " << str(this->MassArrayName) << "\n";
  os << indent << "Mass: " << this->Mass << "\n";
  os << indent << "Shepard: " << this->Shepard << "\n";
  os << indent << "GridFactor: " << this->GridFactor << "\n";
  os << indent << "Method: " << this->Method << "\n";
  os << indent << "SplashThreshold: " << this->SplashThreshold << "\n";
  os << indent << "MaxError: " << this->MaxError << "\n";
  os << indent << "BisectionIterations: " << this->BisectionIterations << "\n";
  os << indent << "Backend: " << this->Backend << "\n";
  os << indent << "Correct: " << this->Correct << "\n";
  os << indent << "Tolerance: " << this->Tolerance << "\n";
  os << indent << "Trim: " << this->Trim << "\n";
  os << indent << "TrimNode: " << this->TrimNode << "\n";
  os << indent << "TrimVertex: " << this->TrimVertex << "\n";
  os << indent << "ComputeNormals: " << this->ComputeNormals << "\n";
  os << indent << "MemoryBudget: " << this->MemoryBudget << "\n";
  os << indent << "FullGrid: " << this->FullGrid << "\n";
  os << indent << "FixedLattice: " << this->FixedLattice << "\n";
  os << indent << "LatticeOrigin: " << this->LatticeOrigin[0] << " " << this->LatticeOrigin[1]
     << " " << this->LatticeOrigin[2] << "\n";
  os << indent << "LatticeCellSize: " << this->LatticeCellSize << "\n";
  os << indent << "PieceAxis: " << this->PieceAxis << "\n";
  os << indent << "PieceBounds: " << this->PieceBounds[0] << " " << this->PieceBounds[1] << "\n";
  os << indent << "PieceParticles: " << this->PieceParticles << "\n";
  os << indent << "CarriedArrays:";
  for (int i = 0; i < this->CarriedArraySelection->GetNumberOfArrays(); ++i)
  {
    const char* name = this->CarriedArraySelection->GetArrayName(i);
    if (name && this->CarriedArraySelection->ArrayIsEnabled(name))
    {
      os << " " << name;
    }
  }
  os << "\n";
  os << indent << "Controller: " << this->Controller << "\n";
  os << indent << "ErrorMessage: " << this->ErrorMessage << "\n";
  os.precision(precision);
}
