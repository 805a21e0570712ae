// Calibrates cameras from an observations CSV (deformcal's format: a header
// `camera,frame,corner,u,v`, then one detected corner per line) through libdeformcal's
// C API, and prints the intrinsics, the convergence status and every frame's pose,
// bend and RMSE.
//
// Build (from the repository root, after cargo build --release):
//   g++ -std=c++17 examples/cpp/calibrate.cpp -Iinclude -Ltarget/release -ldeformcal -Wl,-rpath,$PWD/target/release -o calibrate
// Run, e.g. on a generated dataset:
//   target/release/deformcal generate --preset t2 --images 25 --seed 3 --out t2
//   ./calibrate t2/observations.csv 13 13 0.07 1936 1216 full radial3
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "deformcal.h"

namespace {

struct Csv {
  std::vector<std::string> cameras;  // in order of first appearance
  std::vector<DcObservation> observations;
};

// A number of a CSV field, or false with a message naming the file and line.
bool number(const std::string& field, double* out) {
  char* end = nullptr;
  *out = std::strtod(field.c_str(), &end);
  return !field.empty() && end == field.c_str() + field.size();
}

// Reads an observations CSV; false with a message on stderr for a malformed file.
bool read_csv(const char* path, Csv* csv) {
  std::ifstream in(path);
  if (!in) {
    std::fprintf(stderr, "%s: cannot open\n", path);
    return false;
  }
  std::string line;
  std::getline(in, line);
  if (!line.empty() && line.back() == '\r') line.pop_back();
  if (line != "camera,frame,corner,u,v") {
    std::fprintf(stderr, "%s:1: expected the header camera,frame,corner,u,v\n", path);
    return false;
  }
  std::map<std::string, uint32_t> index;
  for (long number_of_line = 2; std::getline(in, line); ++number_of_line) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    std::vector<std::string> fields;
    std::stringstream row(line);
    for (std::string f; std::getline(row, f, ',');) fields.push_back(f);
    double frame = 0, corner = 0, u = 0, v = 0;
    if (fields.size() != 5 || fields[0].empty() || !number(fields[1], &frame) ||
        !number(fields[2], &corner) || !number(fields[3], &u) || !number(fields[4], &v) ||
        corner < 0 || corner != static_cast<double>(static_cast<uint32_t>(corner)) ||
        frame != static_cast<double>(static_cast<int64_t>(frame))) {
      std::fprintf(stderr, "%s:%ld: expected camera,frame,corner,u,v\n", path, number_of_line);
      return false;
    }
    auto it = index.find(fields[0]);
    if (it == index.end()) {
      it = index.emplace(fields[0], static_cast<uint32_t>(csv->cameras.size())).first;
      csv->cameras.push_back(fields[0]);
    }
    csv->observations.push_back(DcObservation{it->second, static_cast<int64_t>(frame),
                                              static_cast<uint32_t>(corner), u, v});
  }
  return true;
}

void print_vector(const char* name, const double* v) {
  std::printf(" %s %.12g %.12g %.12g", name, v[0], v[1], v[2]);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 7 || argc > 9) {
    std::fprintf(stderr,
                 "usage: %s OBSERVATIONS.csv ROWS COLS SPACING WIDTH HEIGHT [METHOD [MODEL]]\n",
                 argv[0]);
    return 2;
  }
  Csv csv;
  if (!read_csv(argv[1], &csv)) return 1;
  DcTarget target{static_cast<uint32_t>(std::atoi(argv[2])),
                  static_cast<uint32_t>(std::atoi(argv[3])), std::atof(argv[4])};
  const uint32_t width = static_cast<uint32_t>(std::atoi(argv[5]));
  const uint32_t height = static_cast<uint32_t>(std::atoi(argv[6]));
  const char* model = argc > 8 ? argv[8] : "radial3";
  std::vector<DcCamera> cameras;
  for (const std::string& name : csv.cameras) {
    cameras.push_back(DcCamera{name.c_str(), width, height, model});
  }
  DcOptions options{};
  options.method = argc > 7 ? argv[7] : "full";
  DcTolerances tolerances{};  // the defaults; set e.g. function_tolerance = 1e-10 here

  char error[1024];
  // One frame result per distinct frame number of the input.
  std::set<int64_t> frame_numbers;
  for (const DcObservation& o : csv.observations) frame_numbers.insert(o.frame);
  std::vector<DcFrameResult> frames(frame_numbers.size());
  size_t num_frames = 0;
  DcResult result{};
  std::vector<DcCameraResult> intrinsics(cameras.size());
  const int rc = deformcal_calibrate_ex(
      &target, cameras.data(), cameras.size(), csv.observations.data(), csv.observations.size(),
      &options, &tolerances, &result, intrinsics.data(), frames.data(), frames.size(),
      &num_frames, error, sizeof error);
  if (rc != DC_OK && rc != DC_ERROR_FAILED_CHECKS) {
    std::fprintf(stderr, "calibration failed (%d): %s\n", rc, error);
    return 1;
  }
  std::printf("frames %llu observations %llu converged %d iterations %d rmse_px %.12g\n",
              static_cast<unsigned long long>(result.frames),
              static_cast<unsigned long long>(result.observations), result.converged,
              result.iterations, result.rmse_px);
  const char* names[DC_MAX_LENS_PARAMS];
  size_t num_names = 0;
  if (deformcal_lens_params(model, names, DC_MAX_LENS_PARAMS, &num_names, error, sizeof error) !=
      DC_OK) {
    std::fprintf(stderr, "lens parameters: %s\n", error);
    return 1;
  }
  for (size_t k = 0; k < cameras.size(); ++k) {
    std::printf("camera %s", cameras[k].name);
    for (size_t i = 0; i < num_names && i < intrinsics[k].num_params; ++i) {
      std::printf(" %s %.12g", names[i], intrinsics[k].params[i]);
    }
    print_vector("rotation", intrinsics[k].rotation);
    print_vector("translation", intrinsics[k].translation);
    std::printf("\n");
  }
  for (const DcFrameResult& f : frames) {
    std::printf("frame %lld used %d observations %llu rmse_px %.12g",
                static_cast<long long>(f.frame), f.used,
                static_cast<unsigned long long>(f.observations), f.rmse_px);
    print_vector("rotation", f.rotation);
    print_vector("translation", f.translation);
    print_vector("bend", f.bend);
    std::printf(" max_out_of_plane_m %.12g\n", f.max_out_of_plane_m);
  }
  if (rc == DC_ERROR_FAILED_CHECKS) {
    std::fprintf(stderr, "the result is not to be used: %s\n", error);
    return 3;
  }
  return 0;
}
