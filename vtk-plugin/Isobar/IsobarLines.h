// The lines of a text the isobar core hands out one item a line (isobar_surface_warnings,
// isobar_samples_warnings), for the filters that show each as its own message.
#ifndef IsobarLines_h
#define IsobarLines_h

#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

/// The non-empty lines of `text` (NULL and "" have none).
inline std::vector<std::string> IsobarLines(const char* text)
{
  std::vector<std::string> lines;
  std::istringstream in(text ? text : "");
  for (std::string line; std::getline(in, line);)
  {
    if (!line.empty())
    {
      lines.push_back(line);
    }
  }
  return lines;
}

/// Whether `line` is the core's "no surface at isovalue X..." warning; `iso` (unless NULL)
/// gets X, which the core writes in its shortest exact form, so strtod gives it back.
/// Under MPI a filter drops this warning when another rank's piece has the surface.
inline bool IsobarNoSurfaceWarning(const std::string& line, double* iso = nullptr)
{
  static const std::string prefix = "no surface at isovalue ";
  if (line.rfind(prefix, 0) != 0)
  {
    return false;
  }
  if (iso)
  {
    *iso = std::strtod(line.c_str() + prefix.size(), nullptr);
  }
  return true;
}

#endif
