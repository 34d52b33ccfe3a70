/* pendulum-cosim: the plant core of a plant FMU (implements core_api.h).
 *
 * The model-specific parts come from two generated files:
 *   model_config.h  - the schema of fmu_models.export.config: groups P (parameters), STEP
 *                     (step_size), X (states), DX (derivatives), U (inputs), W (process
 *                     noise), Y (measured outputs), IP (integrator, substeps), TIME; and the
 *                     plant's X_START[] and DEFAULT_STEP_SIZE
 *   model_funcs.h   - CasADi-generated f, h, jac_f, jac_h (dense outputs, column-major)
 * This file and plant_core.c are generic over both plants and both FMI versions:
 * every check on values lives here, the wrappers only translate calls.
 */
#ifndef PLANT_CORE_H
#define PLANT_CORE_H

#include <stddef.h>
#include "model_config.h"

#define NX N_X
#define NU N_U
#define NY N_Y

#define CORE_HAS_ME 1
#define CORE_HAS_DERIVATIVES 1
#define CORE_NX NX
#define CORE_NAME "plant"

enum { INTEGRATOR_EULER = 1, INTEGRATOR_RK4 = 2 };
#define INTEGRATOR(d) ((int)(d)->ip[IP_INTEGRATOR])
#define SUBSTEPS(d) ((d)->ip[IP_SUBSTEPS])
/* Most internal integration steps in one doStep: a larger communication step is refused
 * (an error instead of a call that never returns). */
#define MAX_INTERNAL_STEPS 10000000L

/* Everything that makes up the FMU state (saved, restored and serialised as one block). */
typedef struct {
    double time;                 /* s */
    double p[NP];                /* model parameters */
    double step_size;            /* s, nominal internal step before division by substeps */
    long long ip[NIP];           /* integrator (INTEGRATOR_EULER or INTEGRATOR_RK4), substeps */
    double x[NX];                /* continuous states */
    double u[NU];                /* inputs */
    double w[NX];                /* additive process noise, applied at the end of doStep */
} CoreData;

/* CasADi work memory for the generated functions. */
typedef struct {
    const double *arg[WORK_ARG];
    double *res[WORK_RES];
    long long int iw[WORK_IW + 1];
    double w[WORK_W + 1];
} CoreWork;

#endif
