/* pendulum-cosim: the core of a signal FMU (implements core_api.h): a source (constant,
 * step, sine, PRBS), a Gaussian noise generator, or a noisy sensor.
 *
 * model_config.h (the schema of fmu_models.export.config, written by fmu_models.export.signal):
 * groups P (Real parameters, `period` first), IP (Integer parameters), IN (the sensor's
 * inputs), OUT (one output per channel), TIME; SIGNAL_KIND; and for the noise and the
 * sensor the first indices of the per-channel parameters in P: SIG_STD, SIG_BIAS, SIG_QUANT.
 *
 * Timing: a signal is sampled at its instants t0 + k period (t0: the start time) and held
 * between them, as the master holds a component's outputs, whatever the communication step.
 * At a communication point on an instant (within SAMPLE_TOL periods) the outputs are the
 * function of that time and of the inputs as set now (a sensor's direct feedthrough); after
 * a doStep that ends between instants they hold the value of the latest instant, computed
 * from the inputs as held at it. Any step size is accepted.
 *
 * Clocked form (CLOCK_VR defined, FMI 3.0; core_api.h): the inputs and outputs are clocked by
 * the input clock `sample` (interval `period`, which must keep its declared value, first
 * activation at the start time); an activation samples the signal at its time from the
 * inputs as set (direct feedthrough), the outputs hold it until the next activation.
 *
 * Noise (documented generator, equal to cosim.noise.counter_normal): channel c at sample
 * k = round(t / period) draws words i = 2 (k NCH + c) and i + 1 of SplitMix64 seeded with
 * `seed` (word i = mix(seed + (i + 1) 0x9E3779B97F4A7C15), Steele, Lea & Flood 2014),
 * u1 = ((a >> 11) + 1) 2^-53 in (0, 1], u2 = (b >> 11) 2^-53, and the Box-Muller
 * z = sqrt(-2 ln u1) cos(2 pi u2). Random access by k: the same seed gives the same value
 * at the same instant whatever the start time or step size.
 */
#ifndef SIGNAL_CORE_H
#define SIGNAL_CORE_H

#include "model_config.h"

#define NCH N_OUT
#define NIN N_IN

#define CORE_HAS_ME 0
#define CORE_HAS_DERIVATIVES 0
#define CORE_NX 0
#define CORE_NAME "signal"

/* the kinds (macros: the core is specialised with #if SIGNAL_KIND == ...) */
#define KIND_CONSTANT 0
#define KIND_STEP 1
#define KIND_SINE 2
#define KIND_PRBS 3
#define KIND_NOISE 4
#define KIND_SENSOR 5
#define KIND_CUSTOM 99
#define PRBS_MAX_BITS 65535

typedef struct {
    double time;                      /* s */
    double p[NP];                     /* Real parameters */
    long long ip[NIP > 0 ? NIP : 1];  /* Integer parameters */
    double in[NIN > 0 ? NIN : 1];     /* inputs (sensor) at the sample the outputs show */
    double in_set[NIN > 0 ? NIN : 1]; /* inputs as set by the master */
    double t0;                        /* s, the start time: instants t0 + k period */
    double ts;                        /* s, the sample time the outputs show */
    ClockState clk;                   /* the clocked form: activation n at t0 + n period */
#if SIGNAL_KIND == KIND_PRBS
    int nbits;
    unsigned char bits[PRBS_MAX_BITS];
#endif
} CoreData;

typedef struct { int unused; } CoreWork;

#endif
