// The lines of a text the isobar core hands out one item a line (isobar_surface_warnings,
// isobar_samples_warnings), for the filters that show each as its own message.
#ifndef IsobarLines_h
#define IsobarLines_h

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

#endif
