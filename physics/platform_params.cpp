// physics layer — helpers on the fixed platform description; see platform_params.hpp.
#include "physics/platform_params.hpp"

#include <numbers>

namespace omnitwin::physics {

double wheel_alpha(int wheel) { return std::numbers::pi / 4.0 + wheel * std::numbers::pi / 2.0; }

const char* to_string(ModelVariant v) {
  switch (v) {
    case ModelVariant::rollers: return "rollers";
    case ModelVariant::capsule: return "capsule";
  }
  return "?";
}

}  // namespace omnitwin::physics
