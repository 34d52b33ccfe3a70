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

#endif

#if SIGNAL_KIND == KIND_PRBS
/* Fibonacci LFSR taps of a maximal-length sequence, orders 2..16 (as cosim.sources.prbs_bits) */
static const int TAPS[17][4] = {{0}, {0}, {2, 1}, {3, 2}, {4, 3}, {5, 3}, {6, 5}, {7, 6}, {8, 6, 5, 4},
                                {9, 5}, {10, 7}, {11, 9}, {12, 11, 10, 4}, {13, 12, 11, 8}, {14, 13, 12, 2},
                                {15, 14}, {16, 15, 13, 4}};

/* The LFSR of `order` seeded with `seed`: its first n bits into bits[] (bits may be NULL:
 * only the last one is returned). */
static int prbs_run(int order, long long seed, unsigned char *bits, int n) {
    unsigned state = (unsigned)(seed % (1LL << order)), out = 0;
    if (!state) state = 1;
    for (int i = 0; i < n; i++) {
        unsigned bit = 0;
        for (int t = 0; t < 4 && TAPS[order][t]; t++) bit ^= (state >> (TAPS[order][t] - 1)) & 1u;
        out = state & 1u;
        if (bits) bits[i] = (unsigned char)out;
        state = (state >> 1) | (bit << (order - 1));
    }
    return (int)out;
}

static void prbs_fill(CoreData *d) {
    int order = (int)d->ip[IP_ORDER];
    d->nbits = (1 << order) - 1;
    prbs_run(order, d->ip[IP_SEED], d->bits, d->nbits);
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
    memset(&d->clk, 0, sizeof d->clk);
#ifdef CLOCK_VR
    if (d->p[P_PERIOD] != CLOCK_INTERVAL)
        FAIL("parameter period = %g differs from the interval %g s of the constant clock sample", d->p[P_PERIOD],
             CLOCK_INTERVAL);
#endif
    return 0;
}

/* Output channel j at the current time into *v; 1 with the message in err if it cannot be
 * computed (a PRBS before initialization, or a sample index out of range). */
static int output(const CoreData *d, int j, double *v, char *err) {
    const double *p = d->p;
    double t = d->ts;
    (void)j; (void)t; (void)err;
#if SIGNAL_KIND == KIND_CONSTANT
    *v = p[P_VALUE];
#elif SIGNAL_KIND == KIND_STEP
    *v = t >= p[P_T_STEP] - 1e-12 ? p[P_AFTER] : p[P_BEFORE];
#elif SIGNAL_KIND == KIND_SINE
    *v = p[P_OFFSET] + p[P_AMPLITUDE] * sin(2 * 3.141592653589793 * p[P_FREQUENCY] * t + p[P_PHASE]);
#elif SIGNAL_KIND == KIND_PRBS
    double q = floor(t / p[P_BIT_TIME] + 1e-9), r;
    int order = (int)d->ip[IP_ORDER], nbits = (1 << order) - 1, bit;
    if (!isfinite(q)) FAIL("t / bit_time = %g / %g is not finite", t, p[P_BIT_TIME]);
    r = fmod(q, (double)nbits);                     /* exact, whatever the size of q */
    if (r < 0) r += (double)nbits;
    /* before initialization the bits are not stored yet: run the register up to the bit */
    bit = d->nbits == nbits ? d->bits[(int)r] : prbs_run(order, d->ip[IP_SEED], NULL, (int)r + 1);
    *v = p[P_OFFSET] + (bit ? p[P_AMPLITUDE] : -p[P_AMPLITUDE]);
#elif SIGNAL_KIND == KIND_NOISE || SIGNAL_KIND == KIND_SENSOR
    long long k;
    double q = nearbyint(d->ts / d->p[P_PERIOD]);
    if (!(fabs(q) <= MAX_INSTANTS)) FAIL("sample index t / period = %g / %g is out of range", d->ts, d->p[P_PERIOD]);
    k = (long long)q;
#if SIGNAL_KIND == KIND_NOISE
    *v = p[SIG_STD + j] * counter_normal((uint64_t)d->ip[IP_SEED], k, j);
#else /* y = q(s + bias + std z) */
    double y = d->in[j] + p[SIG_BIAS + j] + p[SIG_STD + j] * counter_normal((uint64_t)d->ip[IP_SEED], k, j);
    double qu = p[SIG_QUANT + j];
    *v = qu > 0 ? nearbyint(y / qu) * qu : y;
#endif
#else /* KIND_CUSTOM: the registered C expression (signal_custom.h) */
    *v = custom_output(d, j, p, t);
#endif
    return 0;
}

/* 1 in *on if the time is (within the tolerance) a sample instant; 1 (message in err) if the
 * time lies out of the supported range. */
static int on_instant(const CoreData *d, int *on, char *err) {
    double P = d->p[P_PERIOD];
    long long k;
    if (instant_of(d->time, d->t0, P, &k, err)) return 1;
    *on = at_instant(d->time, d->t0, P, k);
    return 0;
}

static int get_real(CoreWork *wk, CoreData *d, unsigned r, double *v, char *err) {
    (void)wk;
    if (IN(r, VR_OUT, NCH)) return output(d, (int)(r - VR_OUT), v, err);
    if (IN(r, VR_IN, NIN)) {
        *v = d->in_set[r - VR_IN];
        return 0;
    }
    return get_common_real(d, r, v, err);
}

static int set_real(CoreData *d, unsigned r, double v, int before_run, char *err) {
    if (IN(r, VR_IN, NIN)) {
        /* a sensor passes NaN and inf on; between instants the held sample stays */
        int on = 1;
        if (before_run != 1 && on_instant(d, &on, err)) return 1;
        d->in_set[r - VR_IN] = v;
        if (before_run == 1 || on) d->in[r - VR_IN] = v;
        return 0;
    }
    return set_common_real(d, r, v, before_run, err);
}

CORE_GET_REAL_EACH
CORE_SET_REAL_EACH

CORE_INT_PARAMETERS(d->ip)

CORE_NO_BOOLEANS

int core_do_step(CoreWork *wk, CoreData *d, double t, double h, char *err) {
    double P = d->p[P_PERIOD], t_end = t + h;
    long long k_end, k_now;
    (void)wk;
    if (check_step(t, h, d->time, err)) return 1;
    if (instant_of(t_end, d->t0, P, &k_end, err) || instant_of(t, d->t0, P, &k_now, err)) return 1;
    if (at_instant(t_end, d->t0, P, k_end)) {
        d->ts = t_end;                           /* on an instant: the inputs set there count */
        memcpy(d->in, d->in_set, sizeof d->in);
    } else if (k_end > k_now) {
        d->ts = d->t0 + (double)k_end * P;       /* an instant inside the step: inputs as held */
        memcpy(d->in, d->in_set, sizeof d->in);
    }
    d->time = t_end;
    return 0;
}

int core_check(const CoreData *d, char *err) {
    if (!isfinite(d->time) || !isfinite(d->t0) || !isfinite(d->ts))
        FAIL("the FMU state is invalid: its time is not finite");
    if (check_parameters(d->p, d->ip, err)) return 1;
    if (check_clock_state(&d->clk, err)) return 1;
#if SIGNAL_KIND == KIND_PRBS
    if (d->nbits != 0) {
        int order = (int)d->ip[IP_ORDER];
        if (order < 2 || order > 16 || d->nbits != (1 << order) - 1)
            FAIL("the FMU state is invalid: %d PRBS bits for order %d", d->nbits, order);
    }
    for (int i = 0; i < PRBS_MAX_BITS; i++)
        if (d->bits[i] > 1) FAIL("the FMU state is invalid: PRBS bit %d", i);
#endif
    return 0;
}

#ifdef CLOCK_VR
/* ------------------------------------------------------------------ the clocked form */
CORE_CLOCK_TIMING(d->p[P_PERIOD])

int core_is_clocked(unsigned r) { return IN(r, VR_IN, NIN) || IN(r, VR_OUT, NCH); }

int core_clock_begin(CoreWork *wk, CoreData *d, char *err) {
    (void)wk; (void)err;
    d->ts = d->time;                         /* the outputs: this instant, the inputs as set */
    memcpy(d->in, d->in_set, sizeof d->in);
    return 0;
}

int core_clock_end(CoreWork *wk, CoreData *d, char *err) {
    (void)wk; (void)err;
    d->clk.n += 1;
    return 0;
}
#endif

CORE_NO_MODEL_EXCHANGE("a signal FMU")
