/* The real-number type of the runtime, chosen at generation (options(real=...) in the OCP
 * file, or dopus-gen generate --real): the sizes header sets UNICYCLE_REAL_FLOAT to 1 for
 * single precision (float) and 0 for double. Everything the runtime computes is a
 * unicycle_real; only times (seconds, unicycle_timer.h) are double in both precisions.
 *
 * - UNICYCLE_R(1.5): a literal of the real type (1.5f in float), so no expression is
 *   promoted to double (on a single-precision FPU such as the Cortex-M4F's, double is
 *   emulated in software);
 * - UNICYCLE_PREC(d, f): a constant that depends on the precision (d in double, f in float),
 *   such as tolerances and thresholds tied to the rounding unit;
 * - unicycle_sqrt, unicycle_fabs, ...: the math functions of the real type (sqrtf, fabsf, ...);
 * - UNICYCLE_REAL_EPSILON, _MIN, _MAX, _HUGE: the limits of the type; UNICYCLE_REAL_TINY
 *   (a floor that keeps a scale away from 0, far above the smallest normal number) and
 *   UNICYCLE_REAL_SQRT_TINY (its square root, a floor of a factor that is squared). */
#ifndef UNICYCLE_REAL_H
#define UNICYCLE_REAL_H

/* The macros name functions and limits of <math.h> and <float.h>, which the files that use
 * them include (this header is part of the public one, which includes neither). */
#ifndef UNICYCLE_REAL_FLOAT /* set by the sizes header (or -DUNICYCLE_REAL_FLOAT=0|1 without one) */
#include "unicycle_sizes.h"
#endif

#if UNICYCLE_REAL_FLOAT
typedef float unicycle_real;
#define UNICYCLE_R(x) x##f
#define UNICYCLE_PREC(dbl, flt) flt##f
#define UNICYCLE_REAL_EPSILON FLT_EPSILON
#define UNICYCLE_REAL_MIN FLT_MIN
#define UNICYCLE_REAL_MAX FLT_MAX
#define UNICYCLE_REAL_HUGE HUGE_VALF
#define UNICYCLE_REAL_TINY 1e-30f
#define UNICYCLE_REAL_SQRT_TINY 1e-15f
#define unicycle_sqrt sqrtf
#define unicycle_fabs fabsf
#define unicycle_fmax fmaxf
#define unicycle_fmin fminf
#define unicycle_exp expf
#define unicycle_log logf
#define unicycle_pow powf
#define unicycle_floor floorf
#define unicycle_ceil ceilf
#define unicycle_sin sinf
#define unicycle_cos cosf
#else
typedef double unicycle_real;
#define UNICYCLE_R(x) x
#define UNICYCLE_PREC(dbl, flt) dbl
#define UNICYCLE_REAL_EPSILON DBL_EPSILON
#define UNICYCLE_REAL_MIN DBL_MIN
#define UNICYCLE_REAL_MAX DBL_MAX
#define UNICYCLE_REAL_HUGE HUGE_VAL
#define UNICYCLE_REAL_TINY 1e-300
#define UNICYCLE_REAL_SQRT_TINY 1e-150
#define unicycle_sqrt sqrt
#define unicycle_fabs fabs
#define unicycle_fmax fmax
#define unicycle_fmin fmin
#define unicycle_exp exp
#define unicycle_log log
#define unicycle_pow pow
#define unicycle_floor floor
#define unicycle_ceil ceil
#define unicycle_sin sin
#define unicycle_cos cos
#endif

#endif /* UNICYCLE_REAL_H */
