/* A minimal FMI Co-Simulation driver, compiled for each target with the FMU's binary
 * (tests/fmu_models/test_platforms.py): loads the library, instantiates it, sets inputs
 * u_j(k) = a_j ((37 k + 11 j) mod 101 - 50) / 50 (exact on every platform) before each of N steps of H seconds, and prints the outputs
 * after each step with 17 significant digits.
 *
 *   harness LIB VERSION TOKEN N H "vr:a,vr:a,..." "vr,vr,..." [CLOCK]
 *
 * VERSION is 2 or 3 (Co-Simulation: DoStep from k H to (k + 1) H after the inputs, the
 * outputs after it), or 3se: FMI 3.0 Scheduled Execution of a clocked FMU, CLOCK the value
 * reference of its input clock, whose model partition is activated at t_k = k H after the
 * clocked inputs are set (the standard's Clock Activation Mode sequence: set, activate, get).
 * TOKEN is the FMU's guid / instantiationToken. Exit status 0 only if every call returned OK
 * (and, in 3se, the FMU neither called clockUpdate, having no output or countdown clock, nor
 * left preemption locked after an activation). In 3se logging is on: the FMU's messages go
 * to stderr.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#ifdef _WIN32
#include <windows.h>
static void *open_lib(const char *p) { return (void *)LoadLibraryA(p); }
static void *sym(void *h, const char *n) { return (void *)GetProcAddress((HMODULE)h, n); }
#else
#include <dlfcn.h>
static void *open_lib(const char *p) { return dlopen(p, RTLD_NOW | RTLD_LOCAL); }
static void *sym(void *h, const char *n) { return dlsym(h, n); }
#endif

#define MAXV 64
static void *lib;
static void *need(const char *name) {
    void *f = sym(lib, name);
    if (!f) { fprintf(stderr, "missing %s\n", name); exit(3); }
    return f;
}
#define CHECK(call) do { int s_ = (int)(call); if (s_ != 0) { fprintf(stderr, "%s returned %d\n", #call, s_); return 4; } } while (0)

static void log_fmi2(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...) {
    (void)e; (void)c;
    fprintf(stderr, "[%s %d] %s\n", n, (int)s, m);
}
static void log_fmi3(fmi3InstanceEnvironment e, fmi3Status s, fmi3String c, fmi3String m) {
    (void)e; (void)c;
    fprintf(stderr, "[%d] %s\n", (int)s, m);
}

/* Scheduled Execution callbacks. One thread, no preemption: lock and unlock have nothing to
 * guard and only count their nesting. clockUpdate (Clock Update Mode) is counted: an FMU
 * whose clocks are input clocks of constant interval has nothing to report through it. */
static int clock_updates, preemption_locks;
static void clock_update(fmi3InstanceEnvironment e) { (void)e; clock_updates++; }
static void lock_preemption(void) { preemption_locks++; }
static void unlock_preemption(void) { preemption_locks--; }

static int parse(const char *text, unsigned vr[], double a[]) {
    int n = 0;
    const char *p = text;
    while (*p && n < MAXV) {
        vr[n] = (unsigned)strtoul(p, (char **)&p, 10);
        a[n] = 1.0;
        if (*p == ':') a[n] = strtod(p + 1, (char **)&p);
        n++;
        if (*p == ',') p++;
    }
    return n;
}

int main(int argc, char **argv) {
    unsigned in_vr[MAXV], out_vr[MAXV];
    double amp[MAXV], dummy[MAXV], u[MAXV], y[MAXV];
    int version, steps, nin, nout, se;
    double h;
    se = argc > 2 && strcmp(argv[2], "3se") == 0;
    if (argc != (se ? 9 : 8)) { fprintf(stderr, "usage: harness LIB VERSION TOKEN N H IN OUT [CLOCK]\n"); return 2; }
    lib = open_lib(argv[1]);
    if (!lib) { fprintf(stderr, "cannot load %s\n", argv[1]); return 3; }
    version = atoi(argv[2]);
    steps = atoi(argv[4]);
    h = strtod(argv[5], NULL);
    nin = argv[6][0] ? parse(argv[6], in_vr, amp) : 0;
    nout = parse(argv[7], out_vr, dummy);
    if (version == 2) {
        fmi2CallbackFunctions cb = {log_fmi2, calloc, free, NULL, NULL};
        fmi2Component c = ((fmi2InstantiateTYPE *)need("fmi2Instantiate"))("h", fmi2CoSimulation, argv[3],
                                                                           "file:///tmp", &cb, fmi2False, fmi2False);
        if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
        CHECK(((fmi2SetupExperimentTYPE *)need("fmi2SetupExperiment"))(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CHECK(((fmi2EnterInitializationModeTYPE *)need("fmi2EnterInitializationMode"))(c));
        CHECK(((fmi2ExitInitializationModeTYPE *)need("fmi2ExitInitializationMode"))(c));
        for (int k = 0; k < steps; k++) {
            for (int j = 0; j < nin; j++) u[j] = amp[j] * (double)((37 * k + 11 * j) % 101 - 50) / 50.0;
            CHECK(((fmi2SetRealTYPE *)need("fmi2SetReal"))(c, in_vr, (size_t)nin, u));
            CHECK(((fmi2DoStepTYPE *)need("fmi2DoStep"))(c, k * h, h, fmi2True));
            CHECK(((fmi2GetRealTYPE *)need("fmi2GetReal"))(c, out_vr, (size_t)nout, y));
            for (int j = 0; j < nout; j++) printf("%.17g%c", y[j], j + 1 < nout ? ' ' : '\n');
        }
        CHECK(((fmi2TerminateTYPE *)need("fmi2Terminate"))(c));
        ((fmi2FreeInstanceTYPE *)need("fmi2FreeInstance"))(c);
    } else if (se) {
        fmi3ValueReference clock = (fmi3ValueReference)strtoul(argv[8], NULL, 10);
        fmi3Instance c = ((fmi3InstantiateScheduledExecutionTYPE *)need("fmi3InstantiateScheduledExecution"))(
            "h", argv[3], "/tmp", fmi3False, fmi3True, NULL, log_fmi3, clock_update, lock_preemption,
            unlock_preemption);
        if (!c) { fprintf(stderr, "fmi3InstantiateScheduledExecution failed\n"); return 4; }
        CHECK(((fmi3EnterInitializationModeTYPE *)need("fmi3EnterInitializationMode"))(c, fmi3False, 0.0, 0.0,
                                                                                       fmi3False, 0.0));
        CHECK(((fmi3ExitInitializationModeTYPE *)need("fmi3ExitInitializationMode"))(c));   /* Clock Activation Mode */
        for (int k = 0; k < steps; k++) {
            for (int j = 0; j < nin; j++) u[j] = amp[j] * (double)((37 * k + 11 * j) % 101 - 50) / 50.0;
            CHECK(((fmi3SetFloat64TYPE *)need("fmi3SetFloat64"))(c, in_vr, (size_t)nin, u, (size_t)nin));
            CHECK(((fmi3ActivateModelPartitionTYPE *)need("fmi3ActivateModelPartition"))(c, clock, k * h));
            if (clock_updates || preemption_locks) {
                fprintf(stderr, "activation %d: %d clockUpdate call(s), preemption lock depth %d\n", k, clock_updates,
                        preemption_locks);
                return 4;
            }
            CHECK(((fmi3GetFloat64TYPE *)need("fmi3GetFloat64"))(c, out_vr, (size_t)nout, y, (size_t)nout));
            for (int j = 0; j < nout; j++) printf("%.17g%c", y[j], j + 1 < nout ? ' ' : '\n');
        }
        CHECK(((fmi3TerminateTYPE *)need("fmi3Terminate"))(c));
        ((fmi3FreeInstanceTYPE *)need("fmi3FreeInstance"))(c);
    } else {
        fmi3Boolean event, terminate, early;
        fmi3Float64 last;
        fmi3Instance c = ((fmi3InstantiateCoSimulationTYPE *)need("fmi3InstantiateCoSimulation"))(
            "h", argv[3], "/tmp", fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, log_fmi3, NULL);
        if (!c) { fprintf(stderr, "fmi3InstantiateCoSimulation failed\n"); return 4; }
        CHECK(((fmi3EnterInitializationModeTYPE *)need("fmi3EnterInitializationMode"))(c, fmi3False, 0.0, 0.0,
                                                                                       fmi3False, 0.0));
        CHECK(((fmi3ExitInitializationModeTYPE *)need("fmi3ExitInitializationMode"))(c));
        for (int k = 0; k < steps; k++) {
            for (int j = 0; j < nin; j++) u[j] = amp[j] * (double)((37 * k + 11 * j) % 101 - 50) / 50.0;
            CHECK(((fmi3SetFloat64TYPE *)need("fmi3SetFloat64"))(c, in_vr, (size_t)nin, u, (size_t)nin));
            CHECK(((fmi3DoStepTYPE *)need("fmi3DoStep"))(c, k * h, h, fmi3True, &event, &terminate, &early, &last));
            CHECK(((fmi3GetFloat64TYPE *)need("fmi3GetFloat64"))(c, out_vr, (size_t)nout, y, (size_t)nout));
            for (int j = 0; j < nout; j++) printf("%.17g%c", y[j], j + 1 < nout ? ' ' : '\n');
        }
        CHECK(((fmi3TerminateTYPE *)need("fmi3Terminate"))(c));
        ((fmi3FreeInstanceTYPE *)need("fmi3FreeInstance"))(c);
    }
    return 0;
}
