/* pendulum-cosim: FMI-independent core of a plant FMU.
 *
 * The model-specific parts come from two generated files:
 *   model_config.h  - sizes, value references, names, parameter domains, defaults
 *   model_funcs.h   - CasADi-generated f, h, jac_f, jac_h (dense outputs, column-major)
 * This file and plant_core.c are generic over both plants.
 */
#ifndef PLANT_CORE_H
#define PLANT_CORE_H

#include <stddef.h>
#include "model_config.h"

enum { INTEGRATOR_EULER = 1, INTEGRATOR_RK4 = 2 };
enum { DOMAIN_REAL = 0, DOMAIN_POSITIVE = 1, DOMAIN_NONNEGATIVE = 2, DOMAIN_SIGN = 3 };

/* Everything that makes up the FMU state (saved, restored and serialised as one block). */
typedef struct {
    double time;                 /* s */
    double p[NP];                /* model parameters */
    double step_size;            /* s, nominal internal step before division by substeps */
    int integrator;              /* INTEGRATOR_EULER or INTEGRATOR_RK4 */
    int substeps;                /* internal steps per step_size */
    double x[NX];                /* continuous states */
    double u[NU];                /* inputs */
    double w[NX];                /* additive process noise, applied at the end of doStep */
} PlantData;

/* CasADi work memory for the generated functions. */
typedef struct {
    const double *arg[WORK_ARG];
    double *res[WORK_RES];
    long long int iw[WORK_IW + 1];
    double w[WORK_W + 1];
} PlantWork;

void plant_defaults(PlantData *d);
/* Returns NULL if parameter k may take value v, else a static message. */
const char *plant_check_param(int k, double v);
void plant_f(PlantWork *wk, const PlantData *d, const double *x, double *xdot);
void plant_h(PlantWork *wk, const PlantData *d, double *y);
/* A: NX*NX, B: NX*NU, H: NY*NX, all dense column-major. */
void plant_jacobians(PlantWork *wk, const PlantData *d, double *A, double *B, double *H);
/* Integrate d->x over h seconds (inputs held), then add d->w. Returns 0 on success,
 * 1 if the result is not finite (d left unchanged). */
int plant_advance(PlantWork *wk, PlantData *d, double h);

#endif
