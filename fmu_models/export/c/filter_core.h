/* pendulum-cosim: the estimator core of an estimator FMU (implements core_api.h).
 *
 * model_config.h (the schema of fmu_models.export.config, written by fmu_models.export.filter):
 * groups P (parameters), U (inputs), Y (measurements), OUT (outputs), VALID (valid flags),
 * TIME; the buffer sizes NSTATE, NFIXED, NDIAG, the PERIOD; LESS_LO/LESS_HI (parameter pairs
 * that must be ordered); and where each input and output of the filter's compiled step
 * (flt_step) and initialisation (flt_init) lives in the buffers below (INIT_*, STEP_*, OUT_*).
 *
 * Timing: the filter runs at its own sample instants t_k = t0 + k PERIOD (t0: the start
 * time), whatever communication step the master takes. The update at t_k is the step
 * predict(u as set at the last communication point at or before t_(k-1)) + update(y and the
 * valid flags as set at the last communication point at or before t_k):
 *   - at a communication point that is (within SAMPLE_TOL periods) an instant t_k not yet
 *     committed, the outputs are that update computed from the inputs as set now (once per
 *     set of inputs), so the estimate at t_k uses the measurement at t_k, as the Python
 *     EstimatorComponent does; doStep from that point commits it;
 *   - doStep(t, h) then performs the update of every instant strictly inside (t, t + h) with
 *     the inputs held as set; an instant at t + h is left to the communication point t + h
 *     (where the master may set the measurement of that instant first);
 *   - between instants the outputs hold the latest estimate; a step shorter than a period
 *     only advances time.
 * At the start time the outputs are the initial estimate. The estimate depends directly on
 * y (and the valid flags), never on u at the same instant.
 *
 * Clocked form (CLOCK_VR defined, FMI 3.0; core_api.h): the inputs, measurements, valid
 * flags and outputs are clocked by the input clock `sample` (interval PERIOD, first activation
 * at the start time). Activation 0 shows the initial estimate and takes the input u_0;
 * activation k >= 1 is the update of instant t_k, predicted with the input set at activation
 * k - 1 and updated with the measurements set at activation k; the outputs show it as soon as
 * the activation begins, and its end commits it. No update runs between activations.
 */
#ifndef FILTER_CORE_H
#define FILTER_CORE_H

#include <stddef.h>
#include "model_config.h"

#define NU N_U
#define NY N_Y
#define NOUT N_OUT

#define CORE_HAS_ME 0
#define CORE_HAS_DERIVATIVES 0
#define CORE_NX 0
#define CORE_NAME "filter"

/* Most filter updates in one doStep: a longer communication step is refused. */
#define MAX_UPDATES 10000000L

typedef struct {
    double time;                 /* s */
    double p[NP];                /* parameters */
    double u[NU];                /* inputs: set now */
    double y[NY];                /* measurements: set now */
    int valid[NY];               /* measurement valid flags */
    double u_prev[NU];           /* input of the previous communication point */
    double t0;                   /* s, the start time: instants t0 + k PERIOD */
    long long kc;                /* the latest instant whose update is committed */
    int cand_ok;                 /* cand_* hold the step for the current inputs */
    double state[NSTATE];        /* the filter state (x, P, ...), committed */
    double fixed[NFIXED];        /* the step's fixed inputs, from the parameters */
    double diag[NDIAG];          /* diagnostics of the committed step */
    double cand_state[NSTATE];   /* the candidate step */
    double cand_diag[NDIAG];
    ClockState clk;              /* the clocked form: activation n is the instant t0 + n PERIOD */
} CoreData;

typedef struct {
    CASADI_WORK;
    double status;
} CoreWork;

#endif
