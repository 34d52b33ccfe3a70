/* pendulum-cosim: the estimator core of an estimator FMU (implements core_api.h).
 *
 * model_config.h (the schema of fmu_models.export.config, written by fmu_models.export.filter):
 * groups P (parameters), U (inputs), Y (measurements), OUT (outputs), VALID (valid flags),
 * TIME; the buffer sizes NSTATE, NFIXED, NDIAG, the PERIOD; LESS_LO/LESS_HI (parameter pairs
 * that must be ordered); and where each input and output of the filter's compiled step
 * (flt_step) and initialisation (flt_init) lives in the buffers below (INIT_*, STEP_*, OUT_*).
 *
 * Timing (as the Python EstimatorComponent): at the start time the outputs are the initial
 * estimate; after that, reading an output at t computes, once per set of inputs, the step
 * predict(u held from the previous communication point) + update(y at t) as a candidate,
 * and doStep(t, h) commits it and keeps u for the next prediction. The estimate therefore
 * depends directly on y (and the valid flags), never on u at the same instant. The
 * communication step must equal the filter's period.
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

typedef struct {
    double time;                 /* s */
    double p[NP];                /* parameters */
    double u[NU];                /* inputs: set now */
    double y[NY];                /* measurements: set now */
    int valid[NY];               /* measurement valid flags */
    double u_prev[NU];           /* input of the previous communication point */
    int started;                 /* a doStep happened: outputs are step results */
    int cand_ok;                 /* cand_* hold the step for the current inputs */
    double state[NSTATE];        /* the filter state (x, P, ...), committed */
    double fixed[NFIXED];        /* the step's fixed inputs, from the parameters */
    double diag[NDIAG];          /* diagnostics of the committed step */
    double cand_state[NSTATE];   /* the candidate step */
    double cand_diag[NDIAG];
} CoreData;

typedef struct {
    const double *arg[WORK_ARG];
    double *res[WORK_RES];
    long long int iw[WORK_IW + 1];
    double w[WORK_W + 1];
    double status;
} CoreWork;

#endif
