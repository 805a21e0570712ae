/* deformcal: camera calibration with chessboards that bend while carried.
 *
 * C interface of libdeformcal (shared: -ldeformcal; static: libdeformcal.a plus
 * -lceres -lglog -lpthread -ldl -lm -lstdc++).  Usable from C and C++.
 * Every function returns 0 on success and non-zero on failure, with a message in
 * `error` (NUL-terminated, cut to error_len bytes): 1 = an invalid argument,
 * 2 = the calibration failed (degenerate data, solver failure), 3 = an internal
 * error, 4 = the calibration ran but failed its guard rails (it did not converge,
 * outlier rejection removed over a quarter of the data, or its RMSE is far above
 * what the data support): its results are filled in for inspection, but they are
 * not a calibration to use; `error` gives the reasons and hints.  No function
 * aborts the process or throws.  Structs are only ever added, never changed, so a
 * program built against an older header keeps working. */
#ifndef DEFORMCAL_H
#define DEFORMCAL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A board of rows x cols inner corners, spacing metres apart (corner i = row*cols + col);
 * spacing 0.0001 to 10 m, image sides 1 to 100000 pixels. */
typedef struct DcTarget {
  uint32_t rows;
  uint32_t cols;
  double spacing;
} DcTarget;

/* The most parameters any lens model has. */
#define DC_MAX_LENS_PARAMS 12

/* A camera of the rig; camera 0 is the reference of the rig poses.  model is a
 * lens model name ("radial3", "opencv5", "opencv8", "kb4", "ds",
 * "pinhole"); NULL = "radial3". */
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
  const char* method;   /* "standard", "static", "dynamic", "full" or "auto"; NULL = "auto" (chosen
                         * by cross-validation); the board priors are estimated from the data */
  int32_t robust;       /* 1 = Cauchy loss (default), -1 = plain least squares */
  double loss_scale_px; /* Cauchy scale, 1e-3 to 1e4; 0 = 1 px; else refused */
  int32_t threads;      /* Ceres threads, 1 to 256; 0 = 1 */
  int32_t max_iterations; /* 0 = 100 */
} DcOptions;

/* Return codes. */
#define DC_OK 0
#define DC_ERROR_ARGUMENT 1
#define DC_ERROR_CALIBRATION 2
#define DC_ERROR_INTERNAL 3
#define DC_ERROR_FAILED_CHECKS 4

/* Solver tolerances and the guard rails' RMSE bound for deformcal_calibrate_ex;
 * zero-initialise and set what you need (0 = default; a tolerance above 0.1, negative
 * or NaN is refused). */
typedef struct DcTolerances {
  double function_tolerance;  /* Ceres: relative change of the cost; 0 = 1e-8 */
  double parameter_tolerance; /* Ceres: relative step size; 0 = 1e-6 */
  double gradient_tolerance;  /* Ceres: max-norm of the gradient; 0 = 1e-10 */
  double max_rmse_px;         /* largest RMSE accepted; 0 = the default rules (5 px,
                                 and 10 times the noise floor above 1 px) */
} DcTolerances;

/* Per-frame result, one per distinct frame number of the input, ascending. */
typedef struct DcFrameResult {
  int64_t frame;             /* the caller's frame number */
  int32_t used;              /* 1 = calibrated; 0 = dropped (too few, collinear or
                                inconsistent corners): the values below are 0, rmse NaN */
  double rotation[3];        /* board pose camera-0-from-board, angle-axis, radians */
  double translation[3];     /* metres */
  double bend[3];            /* a, b, c of z = a x^2 + b y^2 + c x y (1/m); 0 for
                                "standard" and "static" */
  double max_out_of_plane_m; /* largest |z| of the bend over the board */
  double rmse_px;            /* RMSE of this frame's observations (all cameras) */
  uint64_t observations;     /* this frame's observations kept (outliers removed) */
} DcFrameResult;

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
  double rmse_px;            /* over every observation kept (docs/conventions.md §3's rmse_px) */
  int32_t converged;         /* 1 = the last solve converged (0 also returns 4) */
  int32_t iterations;        /* over all solver stages */
  uint64_t observations;     /* kept (outliers and dropped frames removed) */
  uint64_t frames;           /* frames kept */
  double max_out_of_plane_m; /* largest bend over all frames */
} DcResult;

/* Calibrates from in-memory observations.  camera_results must hold num_cameras entries.
 * Limits: at most 1 000 000 corners per board and 64 cameras with distinct names;
 * observations more than 2 % outside their image are dropped; outliers beyond 4 sigma
 * are rejected.  A solve that makes no progress or whose cost is not finite fails (2);
 * a result that fails the guard rails is filled in and returns 4. */
int deformcal_calibrate(const DcTarget* target, const DcCamera* cameras, size_t num_cameras,
                        const DcObservation* observations, size_t num_observations,
                        const DcOptions* options, DcResult* result, DcCameraResult* camera_results,
                        char* error, size_t error_len);

/* deformcal_calibrate with solver tolerances (NULL = defaults) and per-frame results.
 * frame_results is NULL or holds frame_capacity entries, which must be at least the
 * number of distinct frame numbers in observations (checked before the work: else
 * 1); *num_frames (when num_frames is not NULL) receives that number. */
int deformcal_calibrate_ex(const DcTarget* target, const DcCamera* cameras, size_t num_cameras,
                           const DcObservation* observations, size_t num_observations,
                           const DcOptions* options, const DcTolerances* tolerances,
                           DcResult* result, DcCameraResult* camera_results,
                           DcFrameResult* frame_results, size_t frame_capacity,
                           size_t* num_frames, char* error, size_t error_len);

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
