// Range checks of the filters' numeric settings. VTK's clamping setters would turn a bad
// value into another one that runs without a word (a negative Max Error into 0, which
// switches the criterion off); the filters refuse it instead, naming the setting.
#ifndef IsobarSettings_h
#define IsobarSettings_h

#include <cmath>
#include <sstream>
#include <string>

/// Collects the first setting outside its range: chain the checks, then read Failure().
class IsobarSettingsCheck
{
public:
  /// `value` >= `lo`.
  IsobarSettingsCheck& AtLeast(const char* label, double value, double lo, const char* note = "")
  {
    return this->Check(label, value, value >= lo, "be >= ", lo, nullptr, 0.0, "", note);
  }
  /// `value` > `lo`.
  IsobarSettingsCheck& Above(const char* label, double value, double lo, const char* note = "")
  {
    return this->Check(label, value, value > lo, "be > ", lo, nullptr, 0.0, "", note);
  }
  /// `lo` <= `value` <= `hi`.
  IsobarSettingsCheck& Within(
    const char* label, double value, double lo, double hi, const char* note = "")
  {
    return this->Check(label, value, value >= lo && value <= hi, "lie in [", lo, ", ", hi, "]", note);
  }
  /// `lo` < `value` < `hi`.
  IsobarSettingsCheck& Inside(
    const char* label, double value, double lo, double hi, const char* note = "")
  {
    return this->Check(label, value, value > lo && value < hi, "lie in (", lo, ", ", hi, ")", note);
  }
  /// "" when every check passed, else "LABEL must RULE (NOTE), got VALUE" of the first.
  const std::string& Failure() const { return this->First; }

private:
  IsobarSettingsCheck& Check(const char* label, double value, bool ok, const char* rule,
    double lo, const char* between, double hi, const char* close, const char* note)
  {
    // NaN fails every comparison, so it is refused by each rule; infinity is refused too.
    if (this->First.empty() && !(ok && std::isfinite(value)))
    {
      std::ostringstream msg;
      msg.precision(12); // enough to tell a value from its bound, short for people
      msg << label << " must " << rule << lo;
      if (between)
      {
        msg << between << hi << close;
      }
      if (note[0] != '\0')
      {
        msg << " (" << note << ")";
      }
      msg << ", got " << value;
      this->First = msg.str();
    }
    return *this;
  }

  std::string First;
};

#endif
