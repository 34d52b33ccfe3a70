/* pendulum-cosim: modes of an FMU instance (FMI 2.0 and 3.0 wrappers). */
#ifndef WRAPPER_MODES_H
#define WRAPPER_MODES_H

/* Modes of an instance, and masks of the modes in which a call is allowed. */
typedef enum { M_INSTANTIATED, M_INIT, M_STEP, M_EVENT, M_CONT, M_TERMINATED, M_ERROR } Mode;

static const char *mode_name(Mode m) {
    static const char *n[] = {"instantiated", "initialization mode", "step mode", "event mode",
                              "continuous-time mode", "terminated", "error"};
    return n[m];
}

#define B(m) (1u << (m))
#define ANY_LIVE (B(M_INSTANTIATED) | B(M_INIT) | B(M_STEP) | B(M_EVENT) | B(M_CONT) | B(M_TERMINATED))
#define RUNNING (B(M_STEP) | B(M_EVENT) | B(M_CONT))
#define BEFORE_RUN(c) (((1u << (c)->mode) & (B(M_INSTANTIATED) | B(M_INIT))) != 0)

#endif
