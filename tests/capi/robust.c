/* Issue 19 through the C API: every bad call returns non-zero with a message, none
 * aborts; one small calibration succeeds.  Run natively and under valgrind by
 * tests/capi.rs. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "deformcal.h"

static char error[512];

static void report(const char* name, int rc) { printf("%s rc=%d msg=%s\n", name, rc, rc ? error : ""); }

int main(void) {
  DcTarget target;
  uint32_t width, height;
  size_t count = 0;
  report("images_1e9", deformcal_synthetic("t2", 1000000000u, 1, &target, &width, &height, NULL, 0,
                                           &count, error, sizeof error));
  report("stereo", deformcal_synthetic("stereo", 0, 1, &target, &width, &height, NULL, 0, &count,
                                       error, sizeof error));
  int rc = deformcal_synthetic("t2", 8, 3, &target, &width, &height, NULL, 0, &count, error,
                               sizeof error);
  report("count", rc);
  if (rc) return 1;
  DcObservation* obs = calloc(count, sizeof *obs);
  rc = deformcal_synthetic("t2", 8, 3, &target, &width, &height, obs, count, &count, error,
                           sizeof error);
  report("generate", rc);
  if (rc) return 1;
  DcCamera camera = {"cam0", width, height, NULL};
  DcCamera two[2] = {{"cam0", width, height, NULL}, {"cam0", width, height, "opencv5"}};
  DcOptions options;
  memset(&options, 0, sizeof options);
  options.method = "standard";
  DcResult result;
  DcCameraResult cameras[2];

  DcTarget huge = {20000, 20000, 0.07};
  report("target_20000", deformcal_calibrate(&huge, &camera, 1, obs, count, &options, &result,
                                             cameras, error, sizeof error));
  report("result_null", deformcal_calibrate(&target, &camera, 1, obs, count, &options, NULL,
                                            cameras, error, sizeof error));
  report("duplicate_names", deformcal_calibrate(&target, two, 2, obs, count, &options, &result,
                                                cameras, error, sizeof error));
  options.loss_scale_px = -1.0;
  report("scale_negative", deformcal_calibrate(&target, &camera, 1, obs, count, &options, &result,
                                               cameras, error, sizeof error));
  options.loss_scale_px = NAN;
  report("scale_nan", deformcal_calibrate(&target, &camera, 1, obs, count, &options, &result,
                                          cameras, error, sizeof error));
  options.loss_scale_px = 1e9;
  report("scale_huge", deformcal_calibrate(&target, &camera, 1, obs, count, &options, &result,
                                           cameras, error, sizeof error));
  options.loss_scale_px = 0.0;
  rc = deformcal_calibrate(&target, &camera, 1, obs, count, &options, &result, cameras, error,
                           sizeof error);
  report("calibrate", rc);
  if (rc == 0) printf("fx %.3f iterations %d\n", cameras[0].params[0], result.iterations);

  /* deformcal_calibrate_ex: tolerances, per-frame results, the guard rails. */
  DcTolerances tol;
  memset(&tol, 0, sizeof tol);
  DcFrameResult frames[8];
  size_t num_frames = 0;
  tol.function_tolerance = -1.0;
  report("tolerance_negative",
         deformcal_calibrate_ex(&target, &camera, 1, obs, count, &options, &tol, &result, cameras,
                                frames, 8, &num_frames, error, sizeof error));
  tol.function_tolerance = 0.0;
  tol.max_rmse_px = NAN;
  report("max_rmse_nan",
         deformcal_calibrate_ex(&target, &camera, 1, obs, count, &options, &tol, &result, cameras,
                                frames, 8, &num_frames, error, sizeof error));
  tol.max_rmse_px = 0.0;
  report("frames_small",
         deformcal_calibrate_ex(&target, &camera, 1, obs, count, &options, &tol, &result, cameras,
                                frames, 2, &num_frames, error, sizeof error));
  printf("num_frames %zu\n", num_frames);
  options.max_iterations = 1;
  report("not_converged",
         deformcal_calibrate_ex(&target, &camera, 1, obs, count, &options, &tol, &result, cameras,
                                frames, 8, &num_frames, error, sizeof error));
  printf("not_converged converged %d fx_filled %d frame_used %d\n", result.converged,
         cameras[0].params[0] > 0.0, frames[0].used);
  options.max_iterations = 0;
  tol.function_tolerance = 1e-12;
  rc = deformcal_calibrate_ex(&target, &camera, 1, obs, count, &options, &tol, &result, cameras,
                              NULL, 0, NULL, error, sizeof error);
  report("calibrate_ex_no_frames", rc);
  rc = deformcal_calibrate_ex(&target, &camera, 1, obs, count, &options, &tol, &result, cameras,
                              frames, 8, &num_frames, error, sizeof error);
  report("calibrate_ex", rc);
  if (rc == 0) {
    double sum = 0.0;
    for (size_t i = 0; i < num_frames; ++i) sum += frames[i].used ? 1.0 : 0.0;
    printf("frames_used %.0f of %zu frame0 %lld rmse %.4f\n", sum, num_frames,
           (long long)frames[0].frame, frames[0].rmse_px);
  }
  free(obs);
  return 0;
}
