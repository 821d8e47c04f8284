// Which block of a multi-block input a filter is running on, for its error messages.
#ifndef IsobarBlock_h
#define IsobarBlock_h

#include "vtkAlgorithm.h"

#include <cmath>
#include <string>
#include <utility>

/// The leaf block (K of N, K from 1) VTK's composite pipeline runs `algorithm` on, or
/// {0, 0} when the input is not a multi-block one. The pipeline tells a run which block it
/// is only through the progress window it gives it (shift (K-1)/N, scale 1/N, so that each
/// block's progress fills its share of the bar).
inline std::pair<long, long> IsobarBlock(vtkAlgorithm* algorithm)
{
  const double scale = algorithm->GetProgressScale();
  if (!(scale > 0.0 && scale < 1.0))
  {
    return { 0, 0 };
  }
  const long count = std::lround(1.0 / scale);
  const long index = std::lround(algorithm->GetProgressShift() / scale);
  if (count < 2 || index < 0 || index >= count)
  {
    return { 0, 0 };
  }
  return { index + 1, count };
}

/// "block K of N: " for a run on one block of a multi-block input, else "": without it,
/// an error in one block of many would not say which.
inline std::string IsobarBlockPrefix(vtkAlgorithm* algorithm)
{
  const auto [number, count] = IsobarBlock(algorithm);
  if (number == 0)
  {
    return "";
  }
  return "block " + std::to_string(number) + " of " + std::to_string(count) + ": ";
}

/// Starts a run's error text (what GetErrorMessage returns): empty, except on block 2 and
/// later of a multi-block input, where it keeps the earlier blocks' errors. Cleared on
/// every block, it would hold only the last block's error, and none at all when the last
/// block succeeded after another failed.
inline void IsobarBeginErrors(vtkAlgorithm* algorithm, std::string& errors)
{
  if (IsobarBlock(algorithm).first <= 1)
  {
    errors.clear();
  }
}

/// Adds `message`, prefixed with its block (see IsobarBlockPrefix), as a line of `errors`;
/// returns the line.
inline std::string IsobarAddError(vtkAlgorithm* algorithm, std::string& errors, const std::string& message)
{
  std::string line = IsobarBlockPrefix(algorithm) + message;
  errors += (errors.empty() ? "" : "\n") + line;
  return line;
}

#endif
