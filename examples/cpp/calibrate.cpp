// Calibrates a camera from in-memory observations through libdeformcal's C API:
// the built-in T2 preset (25 images, seed 3), method `full`, no files involved.
// Build (from the repository root, after cargo build --release):
//   g++ -std=c++17 examples/cpp/calibrate.cpp -Iinclude -Ltarget/release -ldeformcal -Wl,-rpath,$PWD/target/release -o calibrate
#include <cstdio>
#include <vector>

#include "deformcal.h"

int main() {
  char error[512];
  DcTarget target{};
  uint32_t width = 0, height = 0;
  size_t count = 0;
  if (deformcal_synthetic("t2", 25, 3, &target, &width, &height, nullptr, 0, &count, error,
                          sizeof error) != 0) {
    std::fprintf(stderr, "synthetic data: %s\n", error);
    return 1;
  }
  std::vector<DcObservation> observations(count);
  if (deformcal_synthetic("t2", 25, 3, &target, &width, &height, observations.data(), count,
                          &count, error, sizeof error) != 0) {
    std::fprintf(stderr, "synthetic data: %s\n", error);
    return 1;
  }

  DcCamera camera{"cam0", width, height, "radial3"};
  DcOptions options{};
  options.method = "full";
  DcResult result{};
  DcCameraResult intrinsics{};
  if (deformcal_calibrate(&target, &camera, 1, observations.data(), observations.size(), &options,
                          &result, &intrinsics, error, sizeof error) != 0) {
    std::fprintf(stderr, "calibration failed: %s\n", error);
    return 1;
  }
  std::printf("frames %llu observations %llu converged %d rmse_px %.9f\n",
              static_cast<unsigned long long>(result.frames),
              static_cast<unsigned long long>(result.observations), result.converged,
              result.rmse_px);
  const char* names[DC_MAX_LENS_PARAMS];
  size_t num_names = 0;
  if (deformcal_lens_params(camera.model, names, DC_MAX_LENS_PARAMS, &num_names, error,
                            sizeof error) != 0 ||
      num_names != intrinsics.num_params) {
    std::fprintf(stderr, "lens parameters: %s\n", error);
    return 1;
  }
  for (size_t i = 0; i < num_names; ++i) {
    std::printf("%s%s %.9f", i ? " " : "", names[i], intrinsics.params[i]);
  }
  std::printf("\n");

  // Bad input comes back as an error, not a crash.
  DcTarget bad{0, 0, 0.0};
  if (deformcal_calibrate(&bad, &camera, 1, observations.data(), observations.size(), &options,
                          &result, &intrinsics, error, sizeof error) == 0) {
    std::fprintf(stderr, "a 0 x 0 board was accepted\n");
    return 1;
  }
  std::printf("bad board rejected: %s\n", error);
  return 0;
}
