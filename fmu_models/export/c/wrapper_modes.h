/* pendulum-cosim: the states of an FMU instance (FMI 2.0 and 3.0 wrappers) and masks of the
 * states in which a function may be called.
 *
 * The states are those of the standards' state machines that these FMUs can reach: no
 * asynchronous doStep (FMI 2.0 stepInProgress, stepCanceled), no discarded step, no
 * configuration or Clock Update Mode. Co-Simulation enters Event Mode and Scheduled Execution
 * its Clock Activation Mode only in the clocked form of an FMU (a core that defines
 * CORE_CLOCKED). Every call that returns Error leaves the instance in M_ERROR, where only what
 * the standard allows after an error is accepted (the wrapper's ERROR_CALLS). */
#ifndef WRAPPER_MODES_H
#define WRAPPER_MODES_H

typedef enum { M_INSTANTIATED, M_INIT, M_STEP, M_EVENT, M_CONT, M_TERMINATED, M_ACTIVATION, M_ERROR } Mode;

static const char *mode_name(Mode m) {
    static const char *n[] = {"Instantiated", "Initialization Mode", "Step Mode", "Event Mode",
                              "Continuous-Time Mode", "Terminated", "Clock Activation Mode",
                              "the error state"};
    return (unsigned)m <= (unsigned)M_ERROR ? n[m] : "an unknown state";
}

#define B(m) (1u << (m))
#define LIVE (B(M_INSTANTIATED) | B(M_INIT) | B(M_STEP) | B(M_EVENT) | B(M_CONT) | B(M_TERMINATED) | B(M_ACTIVATION))
#define ANY (LIVE | B(M_ERROR))
#define BEFORE_RUN(c) ((B((c)->mode) & (B(M_INSTANTIATED) | B(M_INIT))) != 0)
/* core_set_real's `before_run`: 1 before the run, 2 in Continuous-Time Mode (where the
 * continuous states may be set too), 0 else. */
#define SET_WHEN(c) (BEFORE_RUN(c) ? 1 : (c)->mode == M_CONT ? 2 : 0)

/* The masks both versions' tables share (Co-Simulation's running state, Model Exchange's); the
 * getters are allowed after an Error with values for debugging only. */
#define CS_RUN B(M_STEP)
#define ME_RUN (B(M_EVENT) | B(M_CONT))
#define GET_ME (B(M_INIT) | ME_RUN | B(M_TERMINATED) | B(M_ERROR))
#define SET_REAL_ME (B(M_INSTANTIATED) | B(M_INIT) | ME_RUN)
#define SET_DISCRETE_ME (B(M_INSTANTIATED) | B(M_INIT) | B(M_EVENT))   /* not in Continuous-Time Mode */

/* Log categories of the modelDescription (<LogCategories>): bits of an instance's `cats`. */
#define CAT_ERROR 1u
#define CAT_ALL_BITS CAT_ERROR

#endif
