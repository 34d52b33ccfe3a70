/* An FMU (FMI 2.0 or 3.0 Model Exchange) as the discrete process model of the filters
 * (see estimators/fmu_model.py).
 *
 * x_{k+1} = f(x_k, u_k): one sample period dt of a fixed-step integrator (forward Euler or the
 * classical Runge-Kutta 4, in equal substeps) over the FMU's right-hand side, with u held;
 * F = df/dx and G = df/du are the exact derivatives of that map: the tangents of the
 * integrator's stages, each stage's Jacobian of the right-hand side from the FMU's directional
 * derivatives (or central differences of its derivatives where it provides none); y = h(x) are
 * the measured outputs or states, H = dh/dx.
 *
 * The FMU is driven through the standard's Model Exchange calls only: instantiated, its
 * parameters set, initialised, the event iteration run, then in Continuous-Time Mode every
 * evaluation restores the state saved there (fmiSetFMUState, where the FMU can), sets the time,
 * the continuous states and the inputs, and reads the derivatives, outputs and directional
 * derivatives. An event inside a sample period (an event indicator changing sign at a substep,
 * CompletedIntegratorStep asking for Event Mode) is a failure: the discretisation would step
 * over it. A failure leaves its message (the first since it was taken) and makes the outputs
 * NaN, so that the filter's step reports a non-finite result and keeps its state; after a call
 * returned Error the instance is restored from its saved state or freed and made again at the
 * next evaluation, after Fatal it is never called again.
 *
 * Compiled once per model with -DFP_PREFIX=<prefix>: every exported name carries the prefix, so
 * the filters' compiled steps call this model's functions by name (CasADi's external-function
 * interface). One context per library; evaluations are serialised by a lock.
 */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#ifdef _WIN32
#include <windows.h>
#define EXPORT __declspec(dllexport)
#define LOAD(path) ((void *)LoadLibraryA(path))
#define SYMBOL(lib, name) ((void *)GetProcAddress((HMODULE)(lib), name))
#else
#include <dlfcn.h>
#define EXPORT __attribute__((visibility("default")))
#define LOAD(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#define SYMBOL(lib, name) dlsym(lib, name)
#endif

#define CAT2(a, b) a##b
#define CAT(a, b) CAT2(a, b)
#define FP(name) CAT(FP_PREFIX, name)
#define JAC(name) CAT(jac_, FP(name))

typedef long long casadi_int;

/* What the Python side passes (FmuConfig in estimators/fmu_model.py, field for field). */
typedef struct {
    int64_t version, nx, nu, ny, nz, npar, method, substeps, directional, restore, completed_step;
    double dt, t0;
    const char *library, *instance_name, *token, *resources;
    const uint32_t *vr_x, *vr_dx, *vr_u, *vr_y, *vr_par;
    const int64_t *y_state;                 /* per measurement: its state index, or -1 (an output) */
    const double *nominal_x, *nominal_u, *u_start, *par;
    const char *const *x_names, *const *y_names;
} fp_config;

enum { EULER = 0, RK4 = 1 };
enum { ST_OK = 0, ST_WARNING = 1, ST_DISCARD = 2, ST_ERROR = 3, ST_FATAL = 4 };
static const char *STATUS[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};

typedef struct {
    fp_config c;
    void *lib, *inst, *saved;
    int dead;                              /* Fatal: the instance is abandoned */
    int errored;                           /* a call returned Error; restored at the next evaluation */
    int failures;                          /* failed evaluations since the message was taken */
    int numerical;                         /* the first of them was a non-finite value */
    char message[2048], log[512];
    volatile int lock;
    double *w;                             /* work arrays, see fp_alloc */
    double *xin, *uin, *xo, *yo;           /* an evaluation's inputs and results */
    double *xc, *xs, *up, *k[4], *dk[4], *T, *Ts, *J, *Ju, *z0, *z1, *fp, *fm, *y, *un;
    casadi_int sp[6][3];                   /* dense sparsities: x, u, y, F, G, H */
    fmi2CallbackFunctions cb;
    struct {                               /* FMI 2.0 */
        fmi2InstantiateTYPE *instantiate;
        fmi2FreeInstanceTYPE *free_instance;
        fmi2SetupExperimentTYPE *setup;
        fmi2EnterInitializationModeTYPE *enter_init;
        fmi2ExitInitializationModeTYPE *exit_init;
        fmi2TerminateTYPE *terminate;
        fmi2SetRealTYPE *set_real;
        fmi2GetRealTYPE *get_real;
        fmi2NewDiscreteStatesTYPE *new_discrete;
        fmi2EnterContinuousTimeModeTYPE *enter_ct;
        fmi2SetTimeTYPE *set_time;
        fmi2SetContinuousStatesTYPE *set_x;
        fmi2GetDerivativesTYPE *derivatives;
        fmi2GetEventIndicatorsTYPE *indicators;
        fmi2CompletedIntegratorStepTYPE *completed;
        fmi2GetDirectionalDerivativeTYPE *directional;
        fmi2GetFMUstateTYPE *get_state;
        fmi2SetFMUstateTYPE *set_state;
        fmi2FreeFMUstateTYPE *free_state;
    } f2;
    struct {                               /* FMI 3.0 */
        fmi3InstantiateModelExchangeTYPE *instantiate;
        fmi3FreeInstanceTYPE *free_instance;
        fmi3EnterInitializationModeTYPE *enter_init;
        fmi3ExitInitializationModeTYPE *exit_init;
        fmi3TerminateTYPE *terminate;
        fmi3SetFloat64TYPE *set_real;
        fmi3GetFloat64TYPE *get_real;
        fmi3UpdateDiscreteStatesTYPE *update_discrete;
        fmi3EnterContinuousTimeModeTYPE *enter_ct;
        fmi3SetTimeTYPE *set_time;
        fmi3SetContinuousStatesTYPE *set_x;
        fmi3GetContinuousStateDerivativesTYPE *derivatives;
        fmi3GetEventIndicatorsTYPE *indicators;
        fmi3CompletedIntegratorStepTYPE *completed;
        fmi3GetDirectionalDerivativeTYPE *directional;
        fmi3GetFMUStateTYPE *get_state;
        fmi3SetFMUStateTYPE *set_state;
        fmi3FreeFMUStateTYPE *free_state;
    } f3;
} fp_context;

static fp_context C;

/* ------------------------------------------------------------------ messages and status */
static void fp_fail(const char *fmt, ...) {
    va_list ap;
    size_t n;
    C.failures++;
    if (C.message[0]) return;               /* the first failure is kept until taken */
    va_start(ap, fmt);
    vsnprintf(C.message, sizeof C.message, fmt, ap);
    va_end(ap);
    n = strlen(C.message);
    if (C.log[0] && n + 40 < sizeof C.message)
        snprintf(C.message + n, sizeof C.message - n, " (the FMU logged: %s)", C.log);
}

static void fp_free_instance(void);

/* The outcome of an FMI call: 0 fine (OK, Warning); else the failure is recorded, and after
 * Error the instance is restored at the next evaluation (or freed), after Fatal abandoned. */
static int fp_status(int status, const char *call) {
    if (status <= ST_WARNING) return 0;
    fp_fail("%s returned %s", call, STATUS[status > 5 ? 5 : status]);
    if (status >= ST_FATAL) {
        C.dead = 1;
        C.inst = NULL;                      /* no call at all after Fatal */
        C.saved = NULL;
    } else if (status == ST_ERROR) {
        C.errored = 1;
        if (!(C.c.restore && C.saved && !strstr(call, "FMUState") && !strstr(call, "FMUstate")))
            fp_free_instance();             /* nothing but FreeInstance may follow */
    }
    return 1;
}

static void fp_log2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String message, ...) {
    va_list ap;
    (void)env; (void)name; (void)category;
    if (status < fmi2Warning || !message) return;
    va_start(ap, message);
    vsnprintf(C.log, sizeof C.log, message, ap);
    va_end(ap);
}

static void fp_log3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env; (void)category;
    if (status >= fmi3Warning && message) snprintf(C.log, sizeof C.log, "%s", message);
}

/* ------------------------------------------------------------------ the FMU's calls */
static int set_time(double t) {
    if (C.c.version == 2) return fp_status(C.f2.set_time(C.inst, t), "fmi2SetTime");
    return fp_status(C.f3.set_time(C.inst, t), "fmi3SetTime");
}

static int set_states(const double *x) {
    if (C.c.version == 2) return fp_status(C.f2.set_x(C.inst, x, (size_t)C.c.nx), "fmi2SetContinuousStates");
    return fp_status(C.f3.set_x(C.inst, x, (size_t)C.c.nx), "fmi3SetContinuousStates");
}

static int set_reals(const uint32_t *vr, int64_t n, const double *v, const char *what) {
    if (n == 0) return 0;
    if (C.c.version == 2) return fp_status(C.f2.set_real(C.inst, vr, (size_t)n, v), what[0] ? what : "fmi2SetReal");
    return fp_status(C.f3.set_real(C.inst, vr, (size_t)n, v, (size_t)n), what[0] ? what : "fmi3SetFloat64");
}

static int get_reals(const uint32_t *vr, int64_t n, double *v) {
    if (n == 0) return 0;
    if (C.c.version == 2) return fp_status(C.f2.get_real(C.inst, vr, (size_t)n, v), "fmi2GetReal");
    return fp_status(C.f3.get_real(C.inst, vr, (size_t)n, v, (size_t)n), "fmi3GetFloat64");
}

static void fp_vector(char *out, size_t size, const double *v, int64_t n) {
    size_t used = 0;
    int64_t i;
    out[0] = 0;
    for (i = 0; i < n && used + 32 < size; i++)
        used += (size_t)snprintf(out + used, size - used, "%s%.17g", i ? ", " : "", v[i]);
}

/* The derivatives at the time and states set last; a non-finite one is a failure. */
static int derivatives(double *dx, const double *x, double t) {
    int64_t i;
    char xs[512];
    int st = C.c.version == 2 ? C.f2.derivatives(C.inst, dx, (size_t)C.c.nx)
                              : C.f3.derivatives(C.inst, dx, (size_t)C.c.nx);
    if (fp_status(st, C.c.version == 2 ? "fmi2GetDerivatives" : "fmi3GetContinuousStateDerivatives")) return 1;
    for (i = 0; i < C.c.nx; i++)
        if (!isfinite(dx[i])) {
            fp_vector(xs, sizeof xs, x, C.c.nx);
            if (!C.message[0]) C.numerical = 1;
            fp_fail("the derivative of state %s is %g at t = %.15g s, x = [%s]", C.c.x_names[i], dx[i], t, xs);
            return 1;
        }
    return 0;
}

/* d(unknowns)/d(known) for one known (seed 1): a column of a Jacobian. */
static int directional(const uint32_t *unknowns, int64_t n, uint32_t known, double *out) {
    const double one = 1.0;
    if (C.c.version == 2)
        return fp_status(C.f2.directional(C.inst, unknowns, (size_t)n, &known, 1, &one, out),
                         "fmi2GetDirectionalDerivative");
    return fp_status(C.f3.directional(C.inst, unknowns, (size_t)n, &known, 1, &one, 1, out, (size_t)n),
                     "fmi3GetDirectionalDerivative");
}

static int indicators(double *z) {
    if (C.c.nz == 0) return 0;
    if (C.c.version == 2) return fp_status(C.f2.indicators(C.inst, z, (size_t)C.c.nz), "fmi2GetEventIndicators");
    return fp_status(C.f3.indicators(C.inst, z, (size_t)C.c.nz), "fmi3GetEventIndicators");
}

/* After a substep: CompletedIntegratorStep (where the FMU needs it and its state can be
 * restored); asking for Event Mode or to terminate is a step event inside the period. */
static int completed_step(double t) {
    int enter = 0, terminate = 0, st;
    if (!C.c.completed_step) return 0;
    if (C.c.version == 2) {
        fmi2Boolean e = fmi2False, s = fmi2False;
        st = C.f2.completed(C.inst, fmi2False, &e, &s);
        enter = e, terminate = s;
    } else {
        fmi3Boolean e = fmi3False, s = fmi3False;
        st = C.f3.completed(C.inst, fmi3False, &e, &s);
        enter = e, terminate = s;
    }
    if (fp_status(st, C.c.version == 2 ? "fmi2CompletedIntegratorStep" : "fmi3CompletedIntegratorStep")) return 1;
    if (enter || terminate) {
        fp_fail("the FMU %s at t = %.15g s, inside a sample period (a step event): the discretisation would "
                "step over it", terminate ? "asked to terminate" : "asked for Event Mode", t);
        return 1;
    }
    return 0;
}

/* ------------------------------------------------------------------ life of the instance */
static void fp_free_instance(void) {
    if (!C.inst) return;
    if (C.c.version == 2) C.f2.free_instance(C.inst);
    else C.f3.free_instance(C.inst);
    C.inst = NULL;
    C.saved = NULL;                         /* freed with the instance */
    C.errored = 0;
}

/* The end the standard allows: Terminate (and the saved state freed) unless a call returned
 * Error since, then FreeInstance; nothing after Fatal. */
static void fp_end(void) {
    if (!C.inst || C.dead) return;
    if (!C.errored) {
        if (C.saved) {
            if (C.c.version == 2) C.f2.free_state(C.inst, &C.saved);
            else C.f3.free_state(C.inst, &C.saved);
        }
        if (C.c.version == 2) C.f2.terminate(C.inst);
        else C.f3.terminate(C.inst);
    }
    fp_free_instance();
}

static int event_iteration(void) {
    int i, needed = 1, terminate = 0, defined = 0;
    double next = 0.0;
    for (i = 0; i < 100 && needed; i++) {
        if (C.c.version == 2) {
            fmi2EventInfo ev;
            memset(&ev, 0, sizeof ev);
            if (fp_status(C.f2.new_discrete(C.inst, &ev), "fmi2NewDiscreteStates")) return 1;
            needed = ev.newDiscreteStatesNeeded, terminate = ev.terminateSimulation;
            defined = ev.nextEventTimeDefined, next = ev.nextEventTime;
        } else {
            fmi3Boolean nd = fmi3False, term = fmi3False, nom = fmi3False, val = fmi3False, def = fmi3False;
            if (fp_status(C.f3.update_discrete(C.inst, &nd, &term, &nom, &val, &def, &next),
                          "fmi3UpdateDiscreteStates")) return 1;
            needed = nd, terminate = term, defined = def;
        }
        if (terminate) {
            fp_fail("the FMU asked to terminate in its initial event iteration");
            return 1;
        }
    }
    if (needed) {
        fp_fail("the FMU's initial event iteration did not converge in 100 iterations");
        return 1;
    }
    if (defined && isfinite(next)) {
        fp_fail("the FMU schedules a time event at t = %.15g s: its dynamics change at given times, which a "
                "discretisation x[k+1] = f(x[k], u[k]) over fixed sample periods would step over", next);
        return 1;
    }
    return 0;
}

static int fp_start2(void) {
    C.cb.logger = fp_log2;
    C.cb.allocateMemory = calloc;
    C.cb.freeMemory = free;
    C.cb.stepFinished = NULL;
    C.cb.componentEnvironment = &C;
    C.inst = C.f2.instantiate(C.c.instance_name, fmi2ModelExchange, C.c.token, C.c.resources, &C.cb, fmi2False,
                              fmi2False);
    if (!C.inst) {
        fp_fail("fmi2Instantiate returned no instance");
        return 1;
    }
    if (set_reals(C.c.vr_par, C.c.npar, C.c.par, "fmi2SetReal (the parameters)")
        || fp_status(C.f2.setup(C.inst, fmi2False, 0.0, C.c.t0, fmi2False, 0.0), "fmi2SetupExperiment")
        || fp_status(C.f2.enter_init(C.inst), "fmi2EnterInitializationMode")
        || fp_status(C.f2.exit_init(C.inst), "fmi2ExitInitializationMode") || event_iteration()
        || fp_status(C.f2.enter_ct(C.inst), "fmi2EnterContinuousTimeMode"))
        return 1;
    if (C.c.restore) return fp_status(C.f2.get_state(C.inst, &C.saved), "fmi2GetFMUstate");
    return 0;
}

static int fp_start3(void) {
    C.inst = C.f3.instantiate(C.c.instance_name, C.c.token, C.c.resources, fmi3False, fmi3False, &C, fp_log3);
    if (!C.inst) {
        fp_fail("fmi3InstantiateModelExchange returned no instance");
        return 1;
    }
    if (set_reals(C.c.vr_par, C.c.npar, C.c.par, "fmi3SetFloat64 (the parameters)")
        || fp_status(C.f3.enter_init(C.inst, fmi3False, 0.0, C.c.t0, fmi3False, 0.0), "fmi3EnterInitializationMode")
        || fp_status(C.f3.exit_init(C.inst), "fmi3ExitInitializationMode") || event_iteration()
        || fp_status(C.f3.enter_ct(C.inst), "fmi3EnterContinuousTimeMode"))
        return 1;
    if (C.c.restore) return fp_status(C.f3.get_state(C.inst, &C.saved), "fmi3GetFMUState");
    return 0;
}

/* The instance in Continuous-Time Mode at t0, restored to its saved state: made (again) if
 * there is none; refused after Fatal. */
static int fp_begin(void) {
    C.log[0] = 0;                           /* what the FMU logs from here belongs to this evaluation */
    if (C.dead) {
        fp_fail("the FMU returned Fatal earlier: it cannot be evaluated again in this process");
        return 1;
    }
    if (!C.inst) {
        if (C.c.version == 2 ? fp_start2() : fp_start3()) {
            fp_end();
            return 1;
        }
        return 0;
    }
    if (C.c.restore && C.saved) {
        if (C.c.version == 2 ? fp_status(C.f2.set_state(C.inst, C.saved), "fmi2SetFMUstate")
                             : fp_status(C.f3.set_state(C.inst, C.saved), "fmi3SetFMUState"))
            return 1;
        C.errored = 0;                      /* the saved state's rules apply again */
    }
    return 0;
}

/* ------------------------------------------------------------------ the discrete map */
/* The values of the unknowns (the derivatives, or outputs) at the state set last. */
static int values(const uint32_t *unknowns, int64_t n, const double *x, double t, double *out) {
    return unknowns == C.c.vr_dx ? derivatives(out, x, t) : get_reals(unknowns, n, out);
}

/* The columns d unknowns / d x_j (n each, column-major into J) at the state x and time t:
 * directional derivatives, or central differences with steps cbrt(eps) max(|x_j|, nominal_j). */
static int state_jacobian(const uint32_t *unknowns, int64_t n, const double *x, double t, double *J) {
    int64_t i, j;
    if (C.c.directional) {
        for (j = 0; j < C.c.nx; j++)
            if (directional(unknowns, n, C.c.vr_x[j], J + j * n)) return 1;
        return 0;
    }
    memcpy(C.xs, x, sizeof(double) * (size_t)C.c.nx);
    for (j = 0; j < C.c.nx; j++) {
        double step = cbrt(DBL_EPSILON) * fmax(fabs(x[j]), C.c.nominal_x[j]), hi = x[j] + step, lo = x[j] - step;
        C.xs[j] = hi;
        if (set_states(C.xs) || values(unknowns, n, C.xs, t, C.un)) return 1;
        C.xs[j] = lo;
        if (set_states(C.xs) || values(unknowns, n, C.xs, t, C.fm)) return 1;
        C.xs[j] = x[j];
        for (i = 0; i < n; i++) J[i + j * n] = (C.un[i] - C.fm[i]) / (hi - lo);
    }
    return 0;
}

/* The right-hand side at (t, x) into k, and with J != NULL its Jacobian in x (nx x nx,
 * column-major), with Ju != NULL also in u (nx x nu): directional derivatives or central
 * differences of the derivatives (steps cbrt(eps) max(|u_j|, nominal_j) for the inputs). */
static int rhs(double t, const double *x, const double *u, double *k, double *J, double *Ju) {
    int64_t n = C.c.nx, j, i;
    if (set_time(t) || set_states(x) || derivatives(k, x, t)) return 1;
    if (!J) return 0;
    if (state_jacobian(C.c.vr_dx, n, x, t, J)) return 1;
    for (j = 0; Ju && j < C.c.nu; j++) {
        double step = cbrt(DBL_EPSILON) * fmax(fabs(u[j]), C.c.nominal_u[j]), hi = u[j] + step, lo = u[j] - step;
        if (C.c.directional) {
            if (directional(C.c.vr_dx, n, C.c.vr_u[j], Ju + j * n)) return 1;
            continue;
        }
        if (set_states(x) || set_reals(C.c.vr_u + j, 1, &hi, "") || derivatives(C.fp, x, t)
            || set_reals(C.c.vr_u + j, 1, &lo, "") || derivatives(C.fm, x, t) || set_reals(C.c.vr_u + j, 1, u + j, ""))
            return 1;
        for (i = 0; i < n; i++) Ju[i + j * n] = (C.fp[i] - C.fm[i]) / (hi - lo);
    }
    return 0;
}

/* dk = Jx Ts + Ju E over the m tangent columns (E: the unit columns of the inputs, after
 * the nx state columns). */
static void stage_tangent(double *dk, const double *Ts, int64_t m) {
    int64_t n = C.c.nx, i, j, l;
    for (j = 0; j < m; j++)
        for (i = 0; i < n; i++) {
            double s = j >= n ? C.Ju[i + (j - n) * n] : 0.0;
            for (l = 0; l < n; l++) s += C.J[i + l * n] * Ts[l + j * n];
            dk[i + j * n] = s;
        }
}

/* One stage: the right-hand side at (t, xs = xc + a k_prev) and its tangent. */
static int stage(int s, double t, double a, const double *u, int64_t m) {
    int64_t n = C.c.nx, i;
    const double *kp = s ? C.k[s - 1] : NULL, *dkp = s ? C.dk[s - 1] : NULL;
    for (i = 0; i < n; i++) C.xs[i] = s ? C.xc[i] + a * kp[i] : C.xc[i];
    if (m) {
        for (i = 0; i < n * m; i++) C.Ts[i] = s ? C.T[i] + a * dkp[i] : C.T[i];
    }
    memcpy(C.up, C.xs, sizeof(double) * (size_t)n);   /* rhs may move C.xs (differences) */
    if (rhs(t, C.up, u, C.k[s], m ? C.J : NULL, m > n ? C.Ju : NULL)) return 1;
    if (m) stage_tangent(C.dk[s], C.Ts, m);
    return 0;
}

/* A state event: an indicator's sign differs between z0 and z1. */
static int crossed(double t) {
    int64_t i;
    for (i = 0; i < C.c.nz; i++)
        if ((C.z0[i] > 0) != (C.z1[i] > 0)) {
            fp_fail("event indicator %lld (of %lld) changes sign inside a sample period (a state event, before t = "
                    "%.15g s): the discretisation would step over it", (long long)i + 1, (long long)C.c.nz, t);
            return 1;
        }
    return 0;
}

/* x (nx), u (nu) -> xn (nx) over one sample period of `substeps` steps; with m > 0 also the
 * tangent T = d xn / d(x, u) of its first m columns (nx: F; nx + nu: F and G). */
static int advance(const double *x, const double *u, int64_t substeps, double *xn, int64_t m) {
    int64_t n = C.c.nx, i, s;
    double h = C.c.dt / (double)substeps;
    if (fp_begin() || set_reals(C.c.vr_u, C.c.nu, u, "")) return 1;
    memcpy(C.xc, x, sizeof(double) * (size_t)n);
    memset(C.T, 0, sizeof(double) * (size_t)(n * m));
    for (i = 0; i < n && m; i++) C.T[i + i * n] = 1.0;
    for (s = 0; s < substeps; s++) {
        double ts = C.c.t0 + (double)s * h;
        if (s == 0 && C.c.nz && (set_time(ts) || set_states(C.xc) || indicators(C.z0))) return 1;
        if (stage(0, ts, 0.0, u, m)) return 1;
        if (C.c.method == RK4) {
            if (stage(1, ts + h / 2, h / 2, u, m) || stage(2, ts + h / 2, h / 2, u, m) || stage(3, ts + h, h, u, m))
                return 1;
            for (i = 0; i < n; i++) C.xc[i] = C.xc[i] + h / 6 * (C.k[0][i] + 2 * C.k[1][i] + 2 * C.k[2][i] + C.k[3][i]);
            for (i = 0; i < n * m; i++)
                C.T[i] = C.T[i] + h / 6 * (C.dk[0][i] + 2 * C.dk[1][i] + 2 * C.dk[2][i] + C.dk[3][i]);
        } else {
            for (i = 0; i < n; i++) C.xc[i] = C.xc[i] + h * C.k[0][i];
            for (i = 0; i < n * m; i++) C.T[i] = C.T[i] + h * C.dk[0][i];
        }
        if (C.c.nz || C.c.completed_step) {
            if (set_time(ts + h) || set_states(C.xc) || indicators(C.z1) || crossed(ts + h)
                || completed_step(ts + h))
                return 1;
            memcpy(C.z0, C.z1, sizeof(double) * (size_t)C.c.nz);
        }
    }
    memcpy(xn, C.xc, sizeof(double) * (size_t)n);
    return 0;
}

/* y = h(x) (ny) and with H != NULL its Jacobian (ny x nx, column-major): a measured state is
 * itself, a measured output is read at t0 with the inputs at their start values. */
static int measure(const double *x, double *y, double *H) {
    int64_t n = C.c.nx, p = C.c.ny, i, j, no = 0, o = 0;
    char xs[512];
    for (i = 0; i < p; i++) no += C.c.y_state[i] < 0;
    if (no && (fp_begin() || set_reals(C.c.vr_u, C.c.nu, C.c.u_start, "") || set_time(C.c.t0) || set_states(x)
               || get_reals(C.c.vr_y, no, C.y) || (H && state_jacobian(C.c.vr_y, no, x, C.c.t0, C.fp))))
        return 1;
    for (i = 0; i < p; i++) {
        int64_t s = C.c.y_state[i];
        y[i] = s >= 0 ? x[s] : C.y[o];
        if (!isfinite(y[i])) {
            fp_vector(xs, sizeof xs, x, n);
            if (!C.message[0]) C.numerical = 1;
            fp_fail("the measurement %s is %g at x = [%s]", C.c.y_names[i], y[i], xs);
            return 1;
        }
        for (j = 0; H && j < n; j++) H[i + j * p] = s >= 0 ? (double)(s == j) : C.fp[o + j * no];
        o += s < 0;
    }
    return 0;
}

/* ------------------------------------------------------------------ the exported interface */
static void lock(void) {
    while (__atomic_test_and_set(&C.lock, __ATOMIC_ACQUIRE)) {
    }
}

static void unlock(void) { __atomic_clear(&C.lock, __ATOMIC_RELEASE); }

static void nan_fill(double *a, int64_t n) {
    int64_t i;
    for (i = 0; a && i < n; i++) a[i] = NAN;
}

/* A CasADi input copied into buf (NULL: all zeros). */
static const double *input(const double *a, double *buf, int64_t n) {
    if (a) memcpy(buf, a, sizeof(double) * (size_t)n);
    else memset(buf, 0, sizeof(double) * (size_t)n);
    return buf;
}

/* The map and its tangent into xn, F (nx x nx), G (nx x nu) where not NULL: NaN on failure. */
static int eval_map(const double **arg, double *xn, double *F, double *G) {
    int64_t n = C.c.nx, nu = C.c.nu, m = G ? n + nu : F ? n : 0;
    lock();
    if (advance(input(arg[0], C.xin, n), input(nu ? arg[1] : NULL, C.uin, nu), C.c.substeps, C.xo, m)) {
        nan_fill(xn, n), nan_fill(F, n * n), nan_fill(G, n * nu);
    } else {
        if (xn) memcpy(xn, C.xo, sizeof(double) * (size_t)n);
        if (F) memcpy(F, C.T, sizeof(double) * (size_t)(n * n));
        if (G) memcpy(G, C.T + n * n, sizeof(double) * (size_t)(n * nu));
    }
    unlock();
    return 0;
}

/* The measurement and its Jacobian into y, H (ny x nx) where not NULL: NaN on failure. */
static int eval_measure(const double **arg, double *y, double *H) {
    int64_t n = C.c.nx, p = C.c.ny;
    lock();
    if (measure(input(arg[0], C.xin, n), C.yo, H)) {
        nan_fill(y, p), nan_fill(H, p * n);
    } else if (y) {
        memcpy(y, C.yo, sizeof(double) * (size_t)p);
    }
    unlock();
    return 0;
}

/* ------------------------------------------------------------------ opening and closing */
static void *symbol(const char *name, int *missing) {
    void *p = SYMBOL(C.lib, name);
    if (!p && !*missing) {
        *missing = 1;
        fp_fail("the FMU's library %s does not export %s", C.c.library, name);
    }
    return p;
}

#define LOAD2(field, name) C.f2.field = (fmi2##name##TYPE *)symbol("fmi2" #name, &missing)
#define LOAD3(field, name) C.f3.field = (fmi3##name##TYPE *)symbol("fmi3" #name, &missing)

static int load_functions(void) {
    int missing = 0;
    if (C.c.version == 2) {
        LOAD2(instantiate, Instantiate); LOAD2(free_instance, FreeInstance); LOAD2(setup, SetupExperiment);
        LOAD2(enter_init, EnterInitializationMode); LOAD2(exit_init, ExitInitializationMode);
        LOAD2(terminate, Terminate); LOAD2(set_real, SetReal); LOAD2(get_real, GetReal);
        LOAD2(new_discrete, NewDiscreteStates); LOAD2(enter_ct, EnterContinuousTimeMode);
        LOAD2(set_time, SetTime); LOAD2(set_x, SetContinuousStates); LOAD2(derivatives, GetDerivatives);
        if (C.c.nz) LOAD2(indicators, GetEventIndicators);
        if (C.c.completed_step) LOAD2(completed, CompletedIntegratorStep);
        if (C.c.directional) LOAD2(directional, GetDirectionalDerivative);
        if (C.c.restore) {
            LOAD2(get_state, GetFMUstate); LOAD2(set_state, SetFMUstate); LOAD2(free_state, FreeFMUstate);
        }
    } else {
        LOAD3(instantiate, InstantiateModelExchange); LOAD3(free_instance, FreeInstance);
        LOAD3(enter_init, EnterInitializationMode); LOAD3(exit_init, ExitInitializationMode);
        LOAD3(terminate, Terminate); LOAD3(set_real, SetFloat64); LOAD3(get_real, GetFloat64);
        LOAD3(update_discrete, UpdateDiscreteStates); LOAD3(enter_ct, EnterContinuousTimeMode);
        LOAD3(set_time, SetTime); LOAD3(set_x, SetContinuousStates);
        LOAD3(derivatives, GetContinuousStateDerivatives);
        if (C.c.nz) LOAD3(indicators, GetEventIndicators);
        if (C.c.completed_step) LOAD3(completed, CompletedIntegratorStep);
        if (C.c.directional) LOAD3(directional, GetDirectionalDerivative);
        if (C.c.restore) {
            LOAD3(get_state, GetFMUState); LOAD3(set_state, SetFMUState); LOAD3(free_state, FreeFMUState);
        }
    }
    return missing;
}

enum { SP_X, SP_U, SP_Y, SP_F, SP_G, SP_H };

static int allocate(void) {
    int64_t n = C.c.nx, nu = C.c.nu, p = C.c.ny, m = n + nu, big = n > p ? n : p, i, used = 0, total;
    double **one[] = {&C.xin, &C.xc, &C.xs, &C.up, &C.xo, &C.k[0], &C.k[1], &C.k[2], &C.k[3]};
    double **tangent[] = {&C.dk[0], &C.dk[1], &C.dk[2], &C.dk[3], &C.T, &C.Ts};
    const casadi_int dims[6][2] = {{n, 1}, {nu, 1}, {p, 1}, {n, n}, {n, nu}, {p, n}};
    total = 9 * n + 6 * n * m + n * n + n * nu + 2 * (C.c.nz + n) + 2 * big * n + 3 * big + nu + 8;
    C.w = (double *)calloc((size_t)total, sizeof(double));
    if (!C.w) {
        fp_fail("out of memory for the model's work arrays");
        return 1;
    }
#define TAKE(ptr, size) (*(ptr) = C.w + used, used += (size))
    for (i = 0; i < 9; i++) TAKE(one[i], n);
    for (i = 0; i < 6; i++) TAKE(tangent[i], n * m);
    TAKE(&C.J, n * n); TAKE(&C.Ju, n * nu); TAKE(&C.z0, C.c.nz + n); TAKE(&C.z1, C.c.nz + n);
    TAKE(&C.fp, big * n); TAKE(&C.fm, big * n); TAKE(&C.y, big); TAKE(&C.yo, big); TAKE(&C.un, big);
    TAKE(&C.uin, nu + 1);
#undef TAKE
    for (i = 0; i < 6; i++) C.sp[i][0] = dims[i][0], C.sp[i][1] = dims[i][1], C.sp[i][2] = 1;
    return 0;
}

/* Load the FMU's library, make and initialise an instance: 0, or 1 with the message (a
 * context opened before, whose opening failed, starts afresh). */
EXPORT int FP(open)(const fp_config *config) {
    int failed;
    lock();
    fp_end();
    free(C.w);
    memset((void *)&C, 0, sizeof C);
    C.lock = 1;                             /* still held */
    C.c = *config;
    failed = allocate();
    if (!failed) {
        C.lib = LOAD(C.c.library);
        if (!C.lib) fp_fail("cannot load the FMU's library %s", C.c.library);
        failed = !C.lib || load_functions() || fp_begin();
    }
    unlock();
    return failed;
}

/* The first failure since the message was taken ("" if none), their number, and whether the
 * first was a non-finite value (else an FMI call, an event or the FMU's state). */
EXPORT const char *FP(message)(void) { return C.message; }

EXPORT int FP(failures)(void) { return C.failures; }

EXPORT int FP(numerical)(void) { return C.numerical; }

EXPORT void FP(clear)(void) {
    lock();
    C.message[0] = 0;
    C.log[0] = 0;
    C.failures = 0;
    C.numerical = 0;
    unlock();
}

/* x_{k+1} of `substeps` steps (the integrator's accuracy check): 0, or 1 with the message. */
EXPORT int FP(advance)(const double *x, const double *u, int64_t substeps, double *xn) {
    int failed;
    lock();
    failed = advance(x, u, substeps, xn, 0);
    unlock();
    return failed;
}

EXPORT void FP(close)(void) {
    lock();
    fp_end();
    unlock();
}

/* ------------------------------------------------------------------ CasADi's external functions */
static const int IN_XU[] = {SP_X, SP_U}, IN_X[] = {SP_X}, OUT_X[] = {SP_X}, OUT_XF[] = {SP_X, SP_F};
static const int OUT_Y[] = {SP_Y}, OUT_YH[] = {SP_Y, SP_H}, IN_XUX[] = {SP_X, SP_U, SP_X}, OUT_FG[] = {SP_F, SP_G};
static const int IN_XY[] = {SP_X, SP_Y}, OUT_H[] = {SP_H};

#define INTERFACE(name, ins, outs)                                                                        \
    EXPORT casadi_int CAT(name, _n_in)(void) { return (casadi_int)(sizeof ins / sizeof ins[0]); }          \
    EXPORT casadi_int CAT(name, _n_out)(void) { return (casadi_int)(sizeof outs / sizeof outs[0]); }       \
    EXPORT const casadi_int *CAT(name, _sparsity_in)(casadi_int i) {                                      \
        return i >= 0 && i < CAT(name, _n_in)() ? C.sp[ins[i]] : NULL;                                     \
    }                                                                                                     \
    EXPORT const casadi_int *CAT(name, _sparsity_out)(casadi_int i) {                                     \
        return i >= 0 && i < CAT(name, _n_out)() ? C.sp[outs[i]] : NULL;                                   \
    }

/* f: (x, u) -> x_{k+1} */
INTERFACE(FP(f), IN_XU, OUT_X)
EXPORT int FP(f)(const double **arg, double **res, casadi_int *iw, double *w, int mem) {
    (void)iw; (void)w; (void)mem;
    return eval_map(arg, res[0], NULL, NULL);
}

/* fF: (x, u) -> (x_{k+1}, F) */
INTERFACE(FP(fF), IN_XU, OUT_XF)
EXPORT int FP(fF)(const double **arg, double **res, casadi_int *iw, double *w, int mem) {
    (void)iw; (void)w; (void)mem;
    return eval_map(arg, res[0], res[1], NULL);
}

/* jac_f: (x, u, x_{k+1}) -> (F, G): the Jacobian CasADi's differentiation of f calls */
INTERFACE(JAC(f), IN_XUX, OUT_FG)
EXPORT int JAC(f)(const double **arg, double **res, casadi_int *iw, double *w, int mem) {
    (void)iw; (void)w; (void)mem;
    return eval_map(arg, NULL, res[0], res[1]);
}

/* h: x -> y */
INTERFACE(FP(h), IN_X, OUT_Y)
EXPORT int FP(h)(const double **arg, double **res, casadi_int *iw, double *w, int mem) {
    (void)iw; (void)w; (void)mem;
    return eval_measure(arg, res[0], NULL);
}

/* hH: x -> (y, H) */
INTERFACE(FP(hH), IN_X, OUT_YH)
EXPORT int FP(hH)(const double **arg, double **res, casadi_int *iw, double *w, int mem) {
    (void)iw; (void)w; (void)mem;
    return eval_measure(arg, res[0], res[1]);
}

/* jac_h: (x, y) -> H */
INTERFACE(JAC(h), IN_XY, OUT_H)
EXPORT int JAC(h)(const double **arg, double **res, casadi_int *iw, double *w, int mem) {
    (void)iw; (void)w; (void)mem;
    return eval_measure(arg, NULL, res[0]);
}
