// Residual functors: observed minus projected pixel of one board corner, for
// every lens model and board model (the registries lens/registry.h and
// board.h).  Knows nothing of how a problem is assembled.
#pragma once

#include "deformcal/cpp/residuals/blocks.h"
#include "deformcal/cpp/residuals/chained.h"
#include "deformcal/cpp/residuals/loss.h"
#include "deformcal/cpp/residuals/pose_only.h"
#include "deformcal/cpp/residuals/reference.h"
#include "deformcal/cpp/residuals/view.h"
