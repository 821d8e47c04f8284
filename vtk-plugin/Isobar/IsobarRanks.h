// What the ranks of a data-parallel run agree on, for the filters that run under MPI.
#ifndef IsobarRanks_h
#define IsobarRanks_h

#include "vtkCommunicator.h"
#include "vtkMultiProcessController.h"

#include <sstream>
#include <string>
#include <vector>

/// The failure of this update as every rank must report it: this rank's own `failure`,
/// else the first other rank's ("rank P failed (see its error message)" or "rank P was
/// cancelled"), else "". `failure` is "" for success and "cancelled" for a cancel. A
/// collective call: every rank makes it, whatever happened to it, so that the ranks go on
/// together (all pieces or none).
inline std::string IsobarAgreeOnFailure(
  vtkMultiProcessController* controller, const std::string& failure)
{
  const int nproc = controller->GetNumberOfProcesses();
  std::vector<int> states(nproc, 0);
  const int state = failure.empty() ? 0 : (failure == "cancelled" ? 2 : 1);
  controller->AllGather(&state, states.data(), 1);
  for (int p = 0; p < nproc && failure.empty(); ++p)
  {
    if (states[p] != 0)
    {
      std::ostringstream msg;
      msg << "rank " << p
          << (states[p] == 2 ? " was cancelled" : " failed (see its error message)");
      return msg.str();
    }
  }
  return failure;
}

#endif
