/* deformcal: camera calibration with chessboards that bend while carried.
 *
 * C interface of libdeformcal (shared: -ldeformcal; static: libdeformcal.a plus
 * -lceres -lglog -lpthread -ldl -lm -lstdc++).  Usable from C and C++.
 * Every function returns 0 on success and non-zero on failure, with a message in
 * `error` (NUL-terminated, cut to error_len bytes): 1 = an invalid argument,
 * 2 = the calibration failed (degenerate data, solver failure), 3 = an internal
 * error.  No function aborts the process or throws. */
#ifndef DEFORMCAL_H
#define DEFORMCAL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A board of rows x cols inner corners, spacing metres apart (corner i = row*cols + col). */
typedef struct DcTarget {
  uint32_t rows;
  uint32_t cols;
  double spacing;
} DcTarget;

/* The most parameters any lens model has. */
#define DC_MAX_LENS_PARAMS 12

/* A camera of the rig; camera 0 is the reference of the rig poses.  model is a
 * lens model name ("radial3", "opencv5", "opencv8", "kb4", "ds"); NULL = "radial3". */
typedef struct DcCamera {
  const char* name;
  uint32_t width;
  uint32_t height;
  const char* model;
} DcCamera;

/* One detected corner; u, v in pixels (integer coordinates are pixel centres). */
typedef struct DcObservation {
  uint32_t camera;
  int64_t frame;
  uint32_t corner;
  double u;
  double v;
} DcObservation;

/* Calibration settings; zero-initialise and set what you need (0 = default). */
typedef struct DcOptions {
  const char* method;   /* "standard", "static", "dynamic" or "full"; NULL = "full" */
  int32_t robust;       /* 1 = Cauchy loss (default), -1 = plain least squares */
  double loss_scale_px; /* Cauchy scale, 1e-3 to 1e4; 0 = 1 px; else refused */
  int32_t threads;      /* Ceres threads, 1 to 256; 0 = 1 */
  int32_t max_iterations; /* 0 = 100 */
} DcOptions;

/* Per-camera result: the lens model's num_params parameters, in the order
 * deformcal_lens_params names them (fx, fy, cx, cy first for every model), and
 * the pose camera-k-from-camera-0. */
typedef struct DcCameraResult {
  uint32_t num_params;
  double params[DC_MAX_LENS_PARAMS];
  double rotation[3];    /* angle-axis, radians */
  double translation[3]; /* metres */
} DcCameraResult;

/* Whole-calibration result. */
typedef struct DcResult {
  double rmse_px;
  int32_t converged;
  int32_t iterations;
  uint64_t observations;
  uint64_t frames;
  double max_out_of_plane_m;
} DcResult;

/* Calibrates from in-memory observations.  camera_results must hold num_cameras entries.
 * Limits: at most 1 000 000 corners per board and 64 cameras with distinct names;
 * observations more than 2 % outside their image are dropped; outliers beyond 4 sigma
 * are rejected.  A solve that makes no progress or whose cost is not finite fails. */
int deformcal_calibrate(const DcTarget* target, const DcCamera* cameras, size_t num_cameras,
                        const DcObservation* observations, size_t num_observations,
                        const DcOptions* options, DcResult* result, DcCameraResult* camera_results,
                        char* error, size_t error_len);

/* The parameter names of a lens model (NULL = "radial3"), static strings.  Call
 * with names = NULL to learn the count, then with room for *count pointers. */
int deformcal_lens_params(const char* model, const char** names, size_t capacity, size_t* count,
                          char* error, size_t error_len);

/* A built-in synthetic dataset ("t1".."t4", "reference") seen by one camera (the rig
 * preset "stereo" is refused); at most 20 000 images.  Call with observations = NULL
 * to learn the count, then with room for *count observations. */
int deformcal_synthetic(const char* preset, uint32_t images, uint64_t seed, DcTarget* target,
                        uint32_t* width, uint32_t* height, DcObservation* observations,
                        size_t capacity, size_t* count, char* error, size_t error_len);

#ifdef __cplusplus
}
#endif

#endif /* DEFORMCAL_H */
