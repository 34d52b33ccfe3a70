/* pendulum-cosim: FMI-independent core of a signal FMU (see signal_core.h, core_api.h). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include "core_api.h"
#include "core_common.h"

#define IN IN_GROUP
#define FAIL(...) do { snprintf(err, ERRLEN, __VA_ARGS__); return 1; } while (0)

#if SIGNAL_KIND == KIND_CUSTOM
#include "signal_custom.h"
#endif


void core_defaults(CoreData *d) {
    memset(d, 0, sizeof(*d));
    for (int k = 0; k < NP; k++) d->p[k] = PARAM_DEFAULT[k];
    for (int k = 0; k < NIP; k++) d->ip[k] = IP_DEFAULT[k];
}

double core_time(const CoreData *d) { return d->time; }
void core_set_time(CoreData *d, double t) { d->time = t; }

#if SIGNAL_KIND == KIND_NOISE || SIGNAL_KIND == KIND_SENSOR
/* ------------------------------------------------------------------ the noise generator */
static uint64_t splitmix64_word(uint64_t seed, uint64_t i) {
    uint64_t z = seed + (i + 1) * 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static double counter_normal(uint64_t seed, long long k, int c) {
    uint64_t i = 2 * ((uint64_t)k * (uint64_t)NCH + (uint64_t)c);
    uint64_t a = splitmix64_word(seed, i), b = splitmix64_word(seed, i + 1);
    double u1 = (double)((a >> 11) + 1) * 0x1.0p-53, u2 = (double)(b >> 11) * 0x1.0p-53;
    return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}

/* round half to even, as numpy.rint */
static long long sample_index(const CoreData *d) { return (long long)nearbyint(d->ts / d->p[P_PERIOD]); }
#endif

#if SIGNAL_KIND == KIND_PRBS
/* Fibonacci LFSR taps of a maximal-length sequence, orders 2..16 (as cosim.sources.prbs_bits) */
static const int TAPS[17][4] = {{0}, {0}, {2, 1}, {3, 2}, {4, 3}, {5, 3}, {6, 5}, {7, 6}, {8, 6, 5, 4},
                                {9, 5}, {10, 7}, {11, 9}, {12, 11, 10, 4}, {13, 12, 11, 8}, {14, 13, 12, 2},
                                {15, 14}, {16, 15, 13, 4}};

static void prbs_fill(CoreData *d) {
    int order = (int)d->ip[IP_ORDER];
    unsigned state = (unsigned)(d->ip[IP_SEED] % (1LL << order));
    if (!state) state = 1;
    d->nbits = (1 << order) - 1;
    for (int i = 0; i < d->nbits; i++) {
        unsigned bit = 0;
        for (int t = 0; t < 4 && TAPS[order][t]; t++) bit ^= (state >> (TAPS[order][t] - 1)) & 1u;
        d->bits[i] = (unsigned char)(state & 1u);
        state = (state >> 1) | (bit << (order - 1));
    }
}
#endif

int core_exit_init(CoreWork *wk, CoreData *d, char *err) {
    (void)wk;
    if (check_parameters(d->p, d->ip, err)) return 1;
#if SIGNAL_KIND == KIND_PRBS
    prbs_fill(d);
#endif
    d->t0 = d->time;
    d->ts = d->time;
    return 0;
}

/* Output channel j at the current time. */
static double output(const CoreData *d, int j) {
    const double *p = d->p;
    double t = d->ts;
    (void)j; (void)t;
#if SIGNAL_KIND == KIND_CONSTANT
    return p[P_VALUE];
#elif SIGNAL_KIND == KIND_STEP
    return t >= p[P_T_STEP] - 1e-12 ? p[P_AFTER] : p[P_BEFORE];
#elif SIGNAL_KIND == KIND_SINE
    return p[P_OFFSET] + p[P_AMPLITUDE] * sin(2 * 3.141592653589793 * p[P_FREQUENCY] * t + p[P_PHASE]);
#elif SIGNAL_KIND == KIND_PRBS
    long long i = (long long)floor(t / p[P_BIT_TIME] + 1e-9) % d->nbits;
    if (i < 0) i += d->nbits;
    return p[P_OFFSET] + (d->bits[i] ? p[P_AMPLITUDE] : -p[P_AMPLITUDE]);
#elif SIGNAL_KIND == KIND_NOISE
    return p[SIG_STD + j] * counter_normal((uint64_t)d->ip[IP_SEED], sample_index(d), j);
#elif SIGNAL_KIND == KIND_SENSOR /* y = q(s + bias + std z) */
    double y = d->in[j] + p[SIG_BIAS + j] + p[SIG_STD + j] * counter_normal((uint64_t)d->ip[IP_SEED], sample_index(d), j);
    double q = p[SIG_QUANT + j];
    return q > 0 ? nearbyint(y / q) * q : y;
#else /* KIND_CUSTOM: the registered C expression (signal_custom.h) */
    return custom_output(d, j, p, t);
#endif
}

/* 1 if the time is (within the tolerance) a sample instant. */
static int on_instant(const CoreData *d) {
    double P = d->p[P_PERIOD];
    return at_instant(d->time, d->t0, P, latest_instant(d->time, d->t0, P));
}

int core_get_real(CoreWork *wk, CoreData *d, const unsigned vr[], size_t n, double v[], char *err) {
    (void)wk;
    for (size_t i = 0; i < n; i++) {
        unsigned r = vr[i];
        if (IN(r, VR_OUT, NCH)) v[i] = output(d, (int)(r - VR_OUT));
        else if (IN(r, VR_P, NP)) v[i] = d->p[r - VR_P];
        else if (IN(r, VR_IN, NIN)) v[i] = d->in_set[r - VR_IN];
        else if (r == VR_TIME) v[i] = d->time;
        else FAIL("no Real variable has value reference %u", r);
    }
    return 0;
}

int core_set_real(CoreData *d, const unsigned vr[], size_t n, const double v[], int before_run, char *err) {
    for (size_t i = 0; i < n; i++) {
        unsigned r = vr[i];
        if (IN(r, VR_P, NP)) {
            if (set_parameter(d->p, (int)(r - VR_P), v[i], before_run, err)) return 1;
        } else if (IN(r, VR_IN, NIN)) {
            /* a sensor passes NaN and inf on; between instants the held sample stays */
            d->in_set[r - VR_IN] = v[i];
            if (before_run || on_instant(d)) d->in[r - VR_IN] = v[i];
        } else FAIL("%s is calculated and cannot be set", r < N_VARS ? VAR_NAMES[r] : "this variable");
    }
    return 0;
}

CORE_INT_PARAMETERS(d->ip)

CORE_NO_BOOLEANS

int core_do_step(CoreWork *wk, CoreData *d, double t, double h, char *err) {
    double P = d->p[P_PERIOD], t_end = t + h;
    long long k_end;
    (void)wk;
    if (!(h > 0) || !isfinite(h)) FAIL("communication step size %g must be > 0", h);
    if (fabs(t - d->time) > 1e-9 * fmax(1.0, fabs(t)))
        FAIL("currentCommunicationPoint %.17g differs from the FMU time %.17g", t, d->time);
    k_end = latest_instant(t_end, d->t0, P);
    if (at_instant(t_end, d->t0, P, k_end)) {
        d->ts = t_end;                           /* on an instant: the inputs set there count */
        memcpy(d->in, d->in_set, sizeof d->in);
    } else if (k_end > latest_instant(t, d->t0, P)) {
        d->ts = d->t0 + (double)k_end * P;       /* an instant inside the step: inputs as held */
        memcpy(d->in, d->in_set, sizeof d->in);
    }
    d->time = t_end;
    return 0;
}

CORE_NO_MODEL_EXCHANGE("a signal FMU")
