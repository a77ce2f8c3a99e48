/* The sine and cosine of one argument in one call, for the generated stage functions.
 *
 * CasADi's C calls sin(a) and cos(a) of the same variable wherever a model has an angle (the
 * derivative of either needs the other), and every libm call reduces the argument by pi/2 on
 * its own (newlib on the Cortex-M: about 70 instructions per call, half of them wrapper and
 * reduction). The generator rewrites each such pair into one call of dopus_sincos
 * (docs/design.md, "The generated stage functions"), which reduces once and evaluates both
 * polynomial kernels on the same square. Double precision only: the float build keeps sinf
 * and cosf.
 *
 * Accuracy: for |x| below DOPUS_SINCOS_REDUCED_MAX (about 2^20 pi/2 = 1.6e6) both results are
 * within 1 ulp of the exact values (tests/test_trig.py measures the error against an
 * extended-precision reference); beyond, and for infinities and NaN, they are libm's sin(x)
 * and cos(x) themselves (errno and all). Signed zeros: sin(-0) = -0. */
#ifndef DOPUS_TRIG_H
#define DOPUS_TRIG_H

#include <float.h>
#include <math.h>

/* The two results of dopus_sincos, returned by value (two doubles: in the registers d0-d1
 * of the ARM hard-float ABI and xmm0-xmm1 of x86-64, no memory round trip). */
typedef struct {
    double s; /* sin(x) */
    double c; /* cos(x) */
} dopus_sincos_pair;

/* |x| reduced here below this bound (n < 2^20 multiples of pi/2, so that n times a 33-bit
 * part of pi/2 is exact); larger arguments go to libm, whose reduction is exact for every
 * double. */
#define DOPUS_SINCOS_REDUCED_MAX 1647099.0

/* dopus_sincos: one argument reduction by pi/2, then the sine and cosine kernels on
 * [-pi/4, pi/4] sharing the square of the reduced argument.
 *
 * The reduction is Cody and Waite's: x = n pi/2 + (y0 + y1) with pi/2 split into parts of 33
 * bits, so that n times a part is exact for n < 2^20; a second and third part are used only
 * when the first subtraction cancels most of the bits (x close to a multiple of pi/2). The
 * constants below are the parts of pi/2 and the minimax coefficients of sin and cos on
 * [-pi/4, pi/4] published with fdlibm (Sun Microsystems, 1993: e_rem_pio2.c, k_sin.c,
 * k_cos.c), which are mathematical constants; the code is this project's. The polynomials
 * differ from sin and cos by less than 2^-58 on that interval (fdlibm's comments); the
 * total error is measured by tests/test_trig.py. The function is static: private to the
 * CasADi file that includes this header, no exported symbol. */

/* How the function is compiled into the CasADi file: inlined at every call by default (GCC
 * and Clang). On the Cortex-M7 that saves about 11 instructions per pair against one
 * out-of-line copy (robot arm, 1151 pairs per instant: 1.011 -> 0.998 M instructions at the
 * operating point) for 51 kB more flash (281 -> 332 kB); -DDOPUS_TRIG_INLINE=static builds
 * the one copy (bench/issue23/measurements.md section 22). */
#ifndef DOPUS_TRIG_INLINE
#if defined(__GNUC__)
#define DOPUS_TRIG_INLINE static inline __attribute__((always_inline))
#else
#define DOPUS_TRIG_INLINE static inline
#endif
#endif

/* 2/pi, and pi/2 in three parts of 33 bits with the remainder after each (fdlibm). */
#define DOPUS_TRIG_INV_PIO2 6.36619772367581382433e-01
#define DOPUS_TRIG_PIO2_1 1.57079632673412561417e+00
#define DOPUS_TRIG_PIO2_1T 6.07710050650619224932e-11
#define DOPUS_TRIG_PIO2_2 6.07710050630396597660e-11
#define DOPUS_TRIG_PIO2_2T 2.02226624879595063154e-21
#define DOPUS_TRIG_PIO2_3 2.02226624871116645580e-21
#define DOPUS_TRIG_PIO2_3T 8.47842766036889956997e-32

/* sin(r) = r + S1 r^3 + ... + S6 r^13 and cos(r) = 1 - r^2/2 + C1 r^4 + ... + C6 r^14 on
 * |r| <= pi/4 (fdlibm's k_sin.c and k_cos.c). */
#define DOPUS_TRIG_S1 -1.66666666666666324348e-01
#define DOPUS_TRIG_S2 8.33333333332248946124e-03
#define DOPUS_TRIG_S3 -1.98412698298579493134e-04
#define DOPUS_TRIG_S4 2.75573137070700676789e-06
#define DOPUS_TRIG_S5 -2.50507602534068634195e-08
#define DOPUS_TRIG_S6 1.58969099521155010221e-10
#define DOPUS_TRIG_C1 4.16666666666666019037e-02
#define DOPUS_TRIG_C2 -1.38888888888741095749e-03
#define DOPUS_TRIG_C3 2.48015872894767294178e-05
#define DOPUS_TRIG_C4 -2.75573143513906633035e-07
#define DOPUS_TRIG_C5 2.08757232129817482790e-09
#define DOPUS_TRIG_C6 -1.13596475577881948265e-11

DOPUS_TRIG_INLINE dopus_sincos_pair dopus_sincos(double x)
{
    dopus_sincos_pair out;
    double fn, r, u, w, y0, ny1, z, rs, rc, hz, one_hz, s, c;
    unsigned q;
    double t = fabs(x);

    if (!(t < DOPUS_SINCOS_REDUCED_MAX)) { /* huge, infinite or NaN: libm's exact reduction */
        out.s = sin(x);
        out.c = cos(x);
        return out;
    }
    /* x = fn pi/2 + (y0 + y1), fn the nearest integer to x 2/pi (0 for |x| < pi/4, where
     * the reduction is exact and leaves y0 = x, y1 = 0) */
#if defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD == 0
    /* rounded to the nearest integer by adding and subtracting 1.5 * 2^52 (exact in double
     * arithmetic with round-to-nearest, |x 2/pi| < 2^51) */
    fn = (x * DOPUS_TRIG_INV_PIO2 + 6755399441055744.0) - 6755399441055744.0;
#else /* wider intermediate results (x87): through the conversion to int instead */
    fn = (double)(int)(x * DOPUS_TRIG_INV_PIO2 + (x < 0.0 ? -0.5 : 0.5));
#endif
    q = (unsigned)(int)fn & 3u;     /* the quadrant, fn modulo 4 */
    r = x - fn * DOPUS_TRIG_PIO2_1; /* exact: fn has at most 20 bits, the part 33 */
    w = fn * DOPUS_TRIG_PIO2_1T;
    y0 = r - w;
    /* cancellation: |y0| more than 2^16 below |x| (a superset of fdlibm's exponent test)
     * needs the second part of pi/2; more than 2^49 below, the third */
    if (fabs(y0) < t * 1.52587890625e-05) {
        u = r;
        w = fn * DOPUS_TRIG_PIO2_2;
        r = u - w;
        w = fn * DOPUS_TRIG_PIO2_2T - ((u - r) - w);
        y0 = r - w;
        if (fabs(y0) < t * 1.7763568394002505e-15) {
            u = r;
            w = fn * DOPUS_TRIG_PIO2_3;
            r = u - w;
            w = fn * DOPUS_TRIG_PIO2_3T - ((u - r) - w);
            y0 = r - w;
        }
    }
    ny1 = (y0 - r) + w; /* -y1, so that sin(-0) = -0 below */

    /* the kernels at y0 + y1, |y0| <= pi/4 (up to rounding), |y1| below half an ulp of y0:
     * sin(y0 + y1) = y0 + y0^3 P(y0^2) + y1 (1 - y0^2/2) and
     * cos(y0 + y1) = 1 - y0^2/2 + y0^4 Q(y0^2) - y0 y1, to the rounding of the last terms
     * (the sine as y0 - (-y1 (1 - y0^2/2) - y0^3 P): for y0 = -0 every term is +0 and the
     * difference keeps the sign of y0) */
    z = y0 * y0;
    hz = 0.5 * z;
    one_hz = 1.0 - hz;
    rs = DOPUS_TRIG_S1 +
         z * (DOPUS_TRIG_S2 +
              z * (DOPUS_TRIG_S3 + z * (DOPUS_TRIG_S4 + z * (DOPUS_TRIG_S5 + z * DOPUS_TRIG_S6))));
    s = y0 - (ny1 * one_hz - (z * y0) * rs);
    rc = DOPUS_TRIG_C1 +
         z * (DOPUS_TRIG_C2 +
              z * (DOPUS_TRIG_C3 + z * (DOPUS_TRIG_C4 + z * (DOPUS_TRIG_C5 + z * DOPUS_TRIG_C6))));
    c = one_hz + (((1.0 - one_hz) - hz) + ((z * z) * rc + y0 * ny1));

    /* sin and cos of x from those of y = x - q pi/2 */
    if (q & 1u) {
        u = s;
        s = c;
        c = -u;
    }
    if (q & 2u) {
        s = -s;
        c = -c;
    }
    out.s = s;
    out.c = c;
    return out;
}

#endif
