// The C++ lens registry: every lens model once, and the one place that names
// them.  Generic code asks it by name (DispatchLens, LensPerCornerWithoutPrior)
// and never names a model.  The Rust registry (src/model/lens/) lists the same
// models; src/solver/bridge_tests.rs checks that both agree on every model's
// parameter count and projection.
#pragma once

#include <string>
#include <type_traits>

#include "deformcal/cpp/lens/common.h"
#include "deformcal/cpp/lens/ds.h"
#include "deformcal/cpp/lens/kb4.h"
#include "deformcal/cpp/lens/opencv5.h"
#include "deformcal/cpp/lens/opencv8.h"
#include "deformcal/cpp/lens/pinhole.h"
#include "deformcal/cpp/lens/radial3.h"

namespace deformcal {

// Fails to compile for a lens struct that lacks a piece common.h lists.
template <class Lens>
constexpr bool CheckLensModel() {
  static_assert(std::is_same_v<decltype(Lens::kName), const char* const>, "kName");
  static_assert(Lens::kNumParams >= 4 && Lens::kNumParams <= kMaxLensParams, "kNumParams");
  static_assert(std::is_same_v<decltype(Lens::kPerCornerWithoutPrior), const bool>,
                "kPerCornerWithoutPrior");
  static_assert(std::is_same_v<decltype(&Lens::template Project<double>),
                               bool (*)(const double*, const double*, double*)>,
                "Project<T>");
  static_assert(std::is_same_v<decltype(&Lens::ProjectWithJacobian),
                               bool (*)(const double*, const double*, double*, double*)>,
                "ProjectWithJacobian");
  return true;
}

// Calls f with a default-constructed model struct whose kName is `name`;
// false when no model has that name.
template <class F>
bool DispatchLens(const std::string& name, F&& f) {
  bool found = false;
  auto try_one = [&](auto lens) {
    static_assert(CheckLensModel<decltype(lens)>());
    if (!found && name == decltype(lens)::kName) {
      found = true;
      f(lens);
    }
  };
  try_one(Radial3{});
  try_one(OpenCv5{});
  try_one(OpenCv8{});
  try_one(Kb4{});
  try_one(DoubleSphere{});
  try_one(Pinhole{});
  return found;
}

// Whether a problem with a camera of this model keeps one block per corner
// unless the lens prior holds the model (kPerCornerWithoutPrior).
inline bool LensPerCornerWithoutPrior(const std::string& name) {
  bool out = false;
  DispatchLens(name, [&](auto lens) { out = decltype(lens)::kPerCornerWithoutPrior; });
  return out;
}

}  // namespace deformcal
