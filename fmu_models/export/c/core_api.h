/* pendulum-cosim: the interface between the FMI wrappers (fmi2_wrapper.c, fmi3_wrapper.c)
 * and a model core. Three cores implement it:
 *   plant_core.c   - a plant from the CasADi model (Model Exchange and Co-Simulation)
 *   filter_core.c  - an estimator: the filter's compiled fused step (Co-Simulation)
 *   signal_core.c  - a source, a noise generator or a noisy sensor (Co-Simulation)
 * The generated core.h of an FMU includes the core's header, which defines CoreData (the
 * whole FMU state, saved and restored as one block), CoreWork (scratch memory) and
 * CORE_HAS_ME, CORE_NX (continuous states), CORE_HAS_DERIVATIVES.
 * Every function returning int returns 0 on success, else 1 with a message in err[ERRLEN].
 */
#ifndef CORE_API_H
#define CORE_API_H

#include <math.h>
#include <stddef.h>

#define ERRLEN 400

/* 1 if the communication point t is not the FMU's time: more than 1e-9 relative to
 * max(1, |t|) apart (fabs(t) compared by hand: no library call for fmax on every step). */
static inline int off_time(double t, double time) {
    return fabs(t - time) > 1e-9 * (fabs(t) > 1.0 ? fabs(t) : 1.0);
}

/* The clocked form (FMI 3.0 only): model_config.h defines CLOCK_VR, the value reference of
 * the input clock `sample` (constant interval: the core's period, shift 0), which clocks the
 * core's inputs and outputs; the core's CoreData then holds `ClockState clk`. The wrapper
 * drives it: in Co-Simulation with Event Mode fmi3SetClock begins an activation and
 * fmi3UpdateDiscreteStates ends it; in Scheduled Execution fmi3ActivateModelPartition does
 * both (the outputs read after it). Activation n is due at t0 + n period. */
typedef struct {
    long long n;     /* activations ended */
    int active;      /* Co-Simulation: the clock is active (set in this super-dense instant) */
    int fresh;       /* Scheduled Execution: the outputs are computed and no input was set since */
} ClockState;

/* The work memory of CasADi-generated functions (the WORK_* sizes of model_config.h): the
 * members a CoreWork begins with in a core that calls them. */
#define CASADI_WORK                \
    const double *arg[WORK_ARG];   \
    double *res[WORK_RES];         \
    long long int iw[WORK_IW + 1]; \
    double w[WORK_W + 1]

/* the core's data types and capabilities */
#include "core.h"

/* integer-typed variables: the width the FMI 3.0 API must use for them */
enum { INT_NONE = 0, INT_32 = 32, INT_64 = 64 };

void core_defaults(CoreData *d);
/* 0 if d is a consistent state of this core (times finite, parameters in their domains,
 * indices in range, ...), else 1 with the reason: checked before an FMU state from outside
 * (deserialised bytes) is used. */
int core_check(const CoreData *d, char *err);
/* leaving initialization mode: check every value, compute the initial state */
int core_exit_init(CoreWork *wk, CoreData *d, char *err);
double core_time(const CoreData *d);
void core_set_time(CoreData *d, double t);

int core_get_real(CoreWork *wk, CoreData *d, const unsigned vr[], size_t n, double v[], char *err);
/* before_run: 1 in the instantiated and initialization modes (parameters may change), 2 in
 * Model Exchange's Continuous-Time Mode (continuous states may be set), else 0 */
int core_set_real(CoreData *d, const unsigned vr[], size_t n, const double v[], int before_run, char *err);
/* width: INT_32 or INT_64 in FMI 3.0 (checked against the variable), INT_NONE in FMI 2.0 */
int core_get_int(const CoreData *d, const unsigned vr[], size_t n, long long v[], int width, char *err);
int core_set_int(CoreData *d, const unsigned vr[], size_t n, const long long v[], int width, int before_run,
                 char *err);
int core_get_bool(const CoreData *d, const unsigned vr[], size_t n, int v[], char *err);
int core_set_bool(CoreData *d, const unsigned vr[], size_t n, const int v[], int before_run, char *err);

/* Co-Simulation: advance from t over h with the inputs held */
int core_do_step(CoreWork *wk, CoreData *d, double t, double h, char *err);

/* Model Exchange (called only when CORE_HAS_ME) */
int core_derivatives(CoreWork *wk, const CoreData *d, double dx[], char *err);
int core_set_states(CoreData *d, const double x[], size_t nx, char *err);
void core_get_states(const CoreData *d, double x[]);
/* directional derivatives (called only when CORE_HAS_DERIVATIVES):
 * sensitivity[i] = sum_k d unknown_i / d known_k * seed[k] */
int core_directional(CoreWork *wk, const CoreData *d, const unsigned unk[], size_t nU, const unsigned kn[],
                     size_t nK, const double seed[], double sens[], char *err);

#ifdef CLOCK_VR
/* 1 if the variable vr is clocked by the sample clock */
int core_is_clocked(unsigned vr);
/* where the next activation lies against t: 0 after it, 1 at it (within the tolerance), 2
 * before it (missed) */
int core_clock_due(const CoreData *d, double t);
double core_clock_next(const CoreData *d);
/* the activation at the current time begins (the outputs then show it) / ends (its update is
 * committed, the next activation is due) */
int core_clock_begin(CoreWork *wk, CoreData *d, char *err);
int core_clock_end(CoreWork *wk, CoreData *d, char *err);
#endif

#endif
