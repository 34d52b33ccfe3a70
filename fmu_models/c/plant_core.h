/* pendulum-cosim: FMI-independent core of a plant FMU.
 *
 * The model-specific parts come from two generated files:
 *   model_config.h  - sizes, value references, names, parameter domains, defaults
 *   model_funcs.h   - CasADi-generated f, h, jac_f, jac_h (dense outputs, column-major)
 * This file and plant_core.c are generic over both plants and both FMI versions:
 * every check on values lives here, the wrappers only translate calls.
 */
#ifndef PLANT_CORE_H
#define PLANT_CORE_H

#include <stddef.h>
#include "model_config.h"

enum { INTEGRATOR_EULER = 1, INTEGRATOR_RK4 = 2 };
enum { DOMAIN_REAL = 0, DOMAIN_POSITIVE = 1, DOMAIN_NONNEGATIVE = 2, DOMAIN_SIGN = 3 };
#define ERRLEN 400

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

#define STATE_MAGIC 0x50435354u /* "PCST" */
typedef struct { unsigned magic; unsigned size; PlantData d; } SavedState;

/* CasADi work memory for the generated functions. */
typedef struct {
    const double *arg[WORK_ARG];
    double *res[WORK_RES];
    long long int iw[WORK_IW + 1];
    double w[WORK_W + 1];
} PlantWork;

void plant_defaults(PlantData *d);
void plant_f(PlantWork *wk, const PlantData *d, const double *x, double *xdot);
void plant_h(PlantWork *wk, const PlantData *d, double *y);
/* A: NX*NX, B: NX*NU, H: NY*NX, all dense column-major. */
void plant_jacobians(PlantWork *wk, const PlantData *d, double *A, double *B, double *H);

/* Each of the following returns 0 on success, else 1 with a message in err[ERRLEN]. */
int plant_check_all(const PlantData *d, char *err);
int plant_get_real(PlantWork *wk, const PlantData *d, const unsigned vr[], size_t n, double v[], char *err);
/* before_run: 1 in the instantiated/initialization modes (fixed parameters may change). */
int plant_set_real(PlantData *d, const unsigned vr[], size_t n, const double v[], int before_run, char *err);
int plant_get_int(const PlantData *d, const unsigned vr[], size_t n, long long v[], char *err);
int plant_set_int(PlantData *d, const unsigned vr[], size_t n, const long long v[], char *err);
int plant_set_states(PlantData *d, const double x[], size_t nx, char *err);
/* sensitivity[i] = sum_k d unknown_i / d known_k * seed[k] */
int plant_directional(PlantWork *wk, const PlantData *d, const unsigned unk[], size_t nU,
                      const unsigned kn[], size_t nK, const double seed[], double sens[], char *err);
/* Integrate over h seconds from time t (inputs held), then add the noise w. */
int plant_do_step(PlantWork *wk, PlantData *d, double t, double h, char *err);
int plant_deserialize(const unsigned char *bytes, size_t size, SavedState *out, char *err);

#endif
