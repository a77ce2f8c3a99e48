/* The real-number type of the runtime, chosen at generation (options(real=...) in the OCP
 * file, or dopus-gen generate --real): the sizes header sets DOPUS_REAL_FLOAT to 1 for
 * single precision (float) and 0 for double. Everything the runtime computes is a
 * dopus_real; only times (seconds, dopus_timer.h) are double in both precisions.
 *
 * - DOPUS_R(1.5): a literal of the real type (1.5f in float), so no expression is
 *   promoted to double (on a single-precision FPU such as the Cortex-M4F's, double is
 *   emulated in software);
 * - DOPUS_PREC(d, f): a constant that depends on the precision (d in double, f in float),
 *   such as tolerances and thresholds tied to the rounding unit;
 * - dopus_sqrt, dopus_fabs, ...: the math functions of the real type (sqrtf, fabsf, ...);
 * - DOPUS_REAL_EPSILON, _MIN, _MAX, _HUGE: the limits of the type; DOPUS_REAL_TINY
 *   (a floor that keeps a scale away from 0, far above the smallest normal number) and
 *   DOPUS_REAL_SQRT_TINY (its square root, a floor of a factor that is squared). */
#ifndef DOPUS_REAL_H
#define DOPUS_REAL_H

/* The macros name functions and limits of <math.h> and <float.h>, which the files that use
 * them include (this header is part of the public one, which includes neither). */
#ifndef DOPUS_REAL_FLOAT /* set by the sizes header (or -DDOPUS_REAL_FLOAT=0|1 without one) */
#include "dopus_sizes.h"
#endif

#if DOPUS_REAL_FLOAT
typedef float dopus_real;
#define DOPUS_R(x) x##f
#define DOPUS_PREC(dbl, flt) flt##f
#define DOPUS_REAL_EPSILON FLT_EPSILON
#define DOPUS_REAL_MIN FLT_MIN
#define DOPUS_REAL_MAX FLT_MAX
#define DOPUS_REAL_HUGE HUGE_VALF
#define DOPUS_REAL_TINY 1e-30f
#define DOPUS_REAL_SQRT_TINY 1e-15f
#define dopus_sqrt sqrtf
#define dopus_fabs fabsf
#define dopus_fmax fmaxf
#define dopus_fmin fminf
#define dopus_exp expf
#define dopus_log logf
#define dopus_pow powf
#define dopus_floor floorf
#define dopus_ceil ceilf
#define dopus_sin sinf
#define dopus_cos cosf
#else
typedef double dopus_real;
#define DOPUS_R(x) x
#define DOPUS_PREC(dbl, flt) dbl
#define DOPUS_REAL_EPSILON DBL_EPSILON
#define DOPUS_REAL_MIN DBL_MIN
#define DOPUS_REAL_MAX DBL_MAX
#define DOPUS_REAL_HUGE HUGE_VAL
#define DOPUS_REAL_TINY 1e-300
#define DOPUS_REAL_SQRT_TINY 1e-150
#define dopus_sqrt sqrt
#define dopus_fabs fabs
#define dopus_fmax fmax
#define dopus_fmin fmin
#define dopus_exp exp
#define dopus_log log
#define dopus_pow pow
#define dopus_floor floor
#define dopus_ceil ceil
#define dopus_sin sin
#define dopus_cos cos
#endif

#endif /* DOPUS_REAL_H */
