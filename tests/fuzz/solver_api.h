/* One source for every generated solver: the tests compile the drivers with
 *   -DSOLVER_PREFIX=<name>_  -DSOLVER_UPREFIX=<NAME>_  -DSOLVER_HEADER='"<name>_solver.h"'
 *   -DPROBLEM_HEADER='"<name>_problem.h"'  -I<generated folder>
 * and these macros give the prefixed names: API(feedback) is <name>_feedback, K(NX) is
 * <NAME>_NX. Only the public API of <name>_solver.h and the problem data of <name>_problem.h
 * (bounds, x0) are used. */
#ifndef FUZZ_SOLVER_API_H
#define FUZZ_SOLVER_API_H

#define FZ_CAT_(a, b) a##b
#define FZ_CAT(a, b) FZ_CAT_(a, b)
#define API(f) FZ_CAT(SOLVER_PREFIX, f)
#define K(n) FZ_CAT(SOLVER_UPREFIX, n)

#include SOLVER_HEADER
#include PROBLEM_HEADER

typedef API(solver) solver_t;

#define N_ K(N)
#define NX K(NX)
#define NU K(NU)
#define NW K(NW)
#define NP K(NP)
#define NG K(NG)
#define NR K(NR)
#define NE K(NE)
/* array sizes that are never zero (C99) */
#define D(n) K(DIM)(n)

/* the highest status code of enum <name>_status */
#define STATUS_MAX K(ERR_DIVERGED)

#endif
