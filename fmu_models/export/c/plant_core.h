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
/* Co-Simulation timing: the state advances on the grid t0 + k step_size alone, whatever the
 * communication step: doStep(t, h) performs the step of every grid instant in (t, t + h]
 * (an instant within SAMPLE_TOL of t + h counts as reached), each step from instant k driven
 * by u and w as set at the last communication point at or before instant k, made of
 * `substeps` integrator steps of step_size / substeps, w added after it. Between grid
 * instants the outputs hold the state of the latest instant; a communication step shorter
 * than step_size only advances time. The run therefore equals the plant's discrete map at
 * step_size for any communication step that divides step_size or is a multiple of it. */

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
    double w[NX];                /* additive process noise, added after each step of step_size */
    /* Co-Simulation: the plant is a sampled system on the grid t0 + k step_size */
    double t0;                   /* s, the start time */
    long long kg;                /* the grid instant the state x belongs to */
    double u_g[NU > 0 ? NU : 1]; /* the input and the noise as set at the last communication */
    double w_g[NX];              /* point at or before grid instant kg (they drive its step) */
} CoreData;

/* CasADi work memory for the generated functions. */
typedef struct {
    CASADI_WORK;
} CoreWork;

#endif
