// The isobar core's progress callback shown as a VTK algorithm's progress, for every
// filter of the module.
#ifndef IsobarProgress_h
#define IsobarProgress_h

#include "vtkAlgorithm.h"

/// Reports `fraction`, with `phase` as the progress text, to `algorithm`'s observers when
/// it moved by a percent, went back (a new pass) or finished: the core reports far more
/// often than observers need. `last` keeps the fraction reported last (-1 before any).
/// Returns whether the user asked to abort, which the core takes as "stop".
inline bool IsobarReportProgress(
  vtkAlgorithm* algorithm, double& last, double fraction, const char* phase)
{
  if (fraction >= 1.0 || fraction - last >= 0.01 || fraction < last)
  {
    last = fraction;
    algorithm->SetProgressText(phase);
    algorithm->UpdateProgress(fraction);
  }
  return algorithm->GetAbortExecute() != 0;
}

#endif
