/* pendulum-cosim call-sequence fuzzer: what the FMI 2.0 and 3.0 drivers share (fuzz.c).
 *
 * An independent model of the standards' state machines: the states an instance of the
 * project's FMUs can reach, the table of the states each function may be called in (written
 * from the standards' text, not from the FMUs' code), and the checks made on every answer.
 */
#ifndef FUZZ_COMMON_H
#define FUZZ_COMMON_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The model's states: I Instantiated, N Initialization Mode, S Step Mode, E Event Mode,
 * C Continuous-Time Mode, T Terminated, A Clock Activation Mode (Scheduled Execution), X after
 * a call returned Error. */
enum { S_INST, S_INIT, S_STEP, S_EVENT, S_CONT, S_TERM, S_ACT, S_ERR, S_COUNT };
static const char STATE_LETTERS[] = "INSECTAX";
static const char *STATE_NAMES[] = {"Instantiated", "InitializationMode", "StepMode", "EventMode",
                                    "ContinuousTimeMode", "Terminated", "ClockActivationMode", "Error"};

/* The answer a call must get: OK, Error, or either (the value decides, or the instance holds
 * a hostile value it accepted before). */
enum { EXP_OK, EXP_ERR, EXP_ANY };
static const char *EXP_NAMES[] = {"OK", "Error", "OK or Error"};

/* One row of the state table: the states (letters) a function may be called in on a
 * Co-Simulation and on a Model Exchange instance ("-": not part of that interface). */
typedef struct { const char *name; const char *cs; const char *me; } Row;

static unsigned letters_mask(const char *s) {
    unsigned m = 0;
    for (; *s; s++) {
        const char *p = strchr(STATE_LETTERS, *s);
        if (p) m |= 1u << (p - STATE_LETTERS);
    }
    return m;
}

/* splitmix64: the generator of every random choice (one stream per sequence). */
typedef struct { uint64_t s; } Rng;
static uint64_t rnd(Rng *r) {
    uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}
static int pick(Rng *r, int n) { return n > 0 ? (int)(rnd(r) % (uint64_t)n) : 0; }
static int chance(Rng *r, double p) { return (double)(rnd(r) >> 11) * 0x1.0p-53 < p; }
static double uniform(Rng *r, double lo, double hi) { return lo + (hi - lo) * (double)(rnd(r) >> 11) * 0x1.0p-53; }

/* Values a hostile caller passes. */
static const double HOSTILE_REALS[] = {NAN, INFINITY, -INFINITY, 1e308, -1e308, 4.9406564584124654e-324,
                                       -2.2250738585072014e-308, 0.0, -0.0, 1e30, -1e30, 1e-300};
static const unsigned HOSTILE_VRS[] = {0x80000000u, 0xFFFFFFFFu, 0x7FFFFFFFu, 100000u, 0xFFFFFFFEu};

#endif
