/* The real-number type of the runtime, chosen at generation (options(real=...) in the OCP
 * file, or dopus-gen generate --real): the sizes header sets ROBOT_ARM_REAL_FLOAT to 1 for
 * single precision (float) and 0 for double. Everything the runtime computes is a
 * robot_arm_real; only times (seconds, robot_arm_timer.h) are double in both precisions.
 *
 * - ROBOT_ARM_R(1.5): a literal of the real type (1.5f in float), so no expression is
 *   promoted to double (on a single-precision FPU such as the Cortex-M4F's, double is
 *   emulated in software);
 * - ROBOT_ARM_PREC(d, f): a constant that depends on the precision (d in double, f in float),
 *   such as tolerances and thresholds tied to the rounding unit;
 * - robot_arm_sqrt, robot_arm_fabs, ...: the math functions of the real type (sqrtf, fabsf, ...);
 * - ROBOT_ARM_REAL_EPSILON, _MIN, _MAX, _HUGE: the limits of the type; ROBOT_ARM_REAL_TINY
 *   (a floor that keeps a scale away from 0, far above the smallest normal number) and
 *   ROBOT_ARM_REAL_SQRT_TINY (its square root, a floor of a factor that is squared). */
#ifndef ROBOT_ARM_REAL_H
#define ROBOT_ARM_REAL_H

/* The macros name functions and limits of <math.h> and <float.h>, which the files that use
 * them include (this header is part of the public one, which includes neither). */
#ifndef ROBOT_ARM_REAL_FLOAT /* set by the sizes header (or -DROBOT_ARM_REAL_FLOAT=0|1 without one) */
#include "robot_arm_sizes.h"
#endif

#if ROBOT_ARM_REAL_FLOAT
typedef float robot_arm_real;
#define ROBOT_ARM_R(x) x##f
#define ROBOT_ARM_PREC(dbl, flt) flt##f
#define ROBOT_ARM_REAL_EPSILON FLT_EPSILON
#define ROBOT_ARM_REAL_MIN FLT_MIN
#define ROBOT_ARM_REAL_MAX FLT_MAX
#define ROBOT_ARM_REAL_HUGE HUGE_VALF
#define ROBOT_ARM_REAL_TINY 1e-30f
#define ROBOT_ARM_REAL_SQRT_TINY 1e-15f
#define robot_arm_sqrt sqrtf
#define robot_arm_fabs fabsf
#define robot_arm_fmax fmaxf
#define robot_arm_fmin fminf
#define robot_arm_exp expf
#define robot_arm_log logf
#define robot_arm_pow powf
#define robot_arm_floor floorf
#define robot_arm_ceil ceilf
#define robot_arm_sin sinf
#define robot_arm_cos cosf
#else
typedef double robot_arm_real;
#define ROBOT_ARM_R(x) x
#define ROBOT_ARM_PREC(dbl, flt) dbl
#define ROBOT_ARM_REAL_EPSILON DBL_EPSILON
#define ROBOT_ARM_REAL_MIN DBL_MIN
#define ROBOT_ARM_REAL_MAX DBL_MAX
#define ROBOT_ARM_REAL_HUGE HUGE_VAL
#define ROBOT_ARM_REAL_TINY 1e-300
#define ROBOT_ARM_REAL_SQRT_TINY 1e-150
#define robot_arm_sqrt sqrt
#define robot_arm_fabs fabs
#define robot_arm_fmax fmax
#define robot_arm_fmin fmin
#define robot_arm_exp exp
#define robot_arm_log log
#define robot_arm_pow pow
#define robot_arm_floor floor
#define robot_arm_ceil ceil
#define robot_arm_sin sin
#define robot_arm_cos cos
#endif

#endif /* ROBOT_ARM_REAL_H */
