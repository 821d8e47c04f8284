// Which block of a multi-block input a filter is running on, for its error messages.
#ifndef IsobarBlock_h
#define IsobarBlock_h

#include "vtkAlgorithm.h"

#include <cmath>
#include <string>

/// "block K of N: " while VTK's composite pipeline runs `algorithm` once per leaf block of
/// a multi-block input (K counts the leaves in traversal order, from 1), else "". The
/// pipeline tells a run which block it is only through the progress window it gives it
/// (shift (K-1)/N, scale 1/N, so that each block's progress fills its share of the bar);
/// without this, an error in one block of many would not say which.
inline std::string IsobarBlockPrefix(vtkAlgorithm* algorithm)
{
  const double scale = algorithm->GetProgressScale();
  if (!(scale > 0.0 && scale < 1.0))
  {
    return "";
  }
  const long count = std::lround(1.0 / scale);
  const long index = std::lround(algorithm->GetProgressShift() / scale);
  if (count < 2 || index < 0 || index >= count)
  {
    return "";
  }
  return "block " + std::to_string(index + 1) + " of " + std::to_string(count) + ": ";
}

#endif
