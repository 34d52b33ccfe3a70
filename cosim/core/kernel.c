/* The co-simulation master's base-step loop in C (see cosim/core/native.py).
 *
 * One generic interpreter, compiled once and cached: the master prepares, per pattern of
 * due components, a program of operations (set inputs by value reference from the signal
 * buffer, doStep, get outputs, a filter's compiled step, a source's value, a call back into
 * Python) and the kernel runs base steps until something needs Python: a Python
 * component's call, a full record buffer, a failed call, a non-finite signal at the end of
 * a block of steps, or the end of the chunk of steps it was given. Its state is kept in
 * kstate_t, so every return can be resumed.
 *
 * Arithmetic is the Python path's, operation for operation (t = t0 + k * h, the same
 * comparisons): compiled with -ffp-contract=off so that no multiply-add is fused.
 *
 * Parallel stepping: the master marks runs of an update phase whose FMUs do not depend on
 * each other (their set-inputs + doStep) as parallel segments, each op with the thread
 * that runs it (lane; thread 0 is the caller). A pool of threads made once per run
 * (kernel_pool_start) runs its lanes of each segment when the caller publishes it; each
 * thread makes its ops in their serial order and stops at its first failure, and the caller
 * reports the first failure in the serial order. Threads wait by spinning for SPIN_SECONDS,
 * then on a condition variable. Measured on a 2-core virtual machine, a hand-over costs
 * some 40 us when the other thread sleeps on a condition variable and under 1 us while it
 * spins; a futex instead of the condition variable would only cheapen the sleeping case,
 * which comes after SPIN_SECONDS of waiting, i.e. when the threads' loads differ by more
 * than that anyway (and a condition variable is portable).
 */
#define _XOPEN_SOURCE 700
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#if defined(__linux__)
#include <sys/prctl.h>
#endif

typedef int (*fmi2_xfer_t)(void *, const unsigned int *, size_t, double *);   /* FMI 1.0's too */
typedef int (*fmi3_xfer_t)(void *, const unsigned int *, size_t, double *, size_t);
typedef int (*fmi1_step_t)(void *, double, double, char);
typedef int (*fmi2_step_t)(void *, double, double, int);
typedef int (*fmi3_step_t)(void *, double, double, bool, bool *, bool *, bool *, double *);
typedef int (*casadi_fn_t)(const double **, double **, long long *, double *, int);

enum {
    OP_PY = 0,       /* a Python callable: return to Python */
    OP_GET = 1,      /* FMI get (Real / Float64), then scatter into the signals */
    OP_SET = 2,      /* gather from the signals, then FMI set (Real / Float64) */
    OP_STEP2 = 3,    /* fmi2DoStep(t, h, true) */
    OP_STEP3 = 4,    /* fmi3DoStep(t, h, true, ...) */
    OP_CONST = 5,    /* values[slot] = a */
    OP_SWITCH = 6,   /* values[slot] = t >= a ? c : b */
    OP_FILTER = 7,   /* a filter's output: its compiled step (after its first instant) */
    OP_HOLD = 8,     /* a filter's update: keep the inputs for the next step */
    OP_HOOK = 9,     /* after a filter's step: its Python hook (if the flag buf[0] is set; no flag: always) */
    OP_SUMMARY = 10, /* a filter's outputs: estimate, covariance entries, NIS */
    OP_NOISE = 11,   /* a noise stream's row of the instant (a new instant: the next row); flag: a sensor */
    OP_PRBS = 12,    /* values[slot] = b + (bits[floor(t / a + 1e-9) mod n] ? c : -c) */
    OP_RECORD = 13,  /* after a filter's step that adapted (flag buf[0]): a row of its noise history */
    OP_STEP1 = 14    /* FMI 1.0 fmiDoStep(t, h, newStep = fmiTrue) */
};

enum {
    EV_DONE = 0,      /* every step ran */
    EV_PY = 1,        /* run the Python callable of op pc, then resume at pc + 1 */
    EV_FAIL = 2,      /* op pc failed (status in the op's result fields) */
    EV_FLUSH = 3,     /* the record buffer is full: flush it, set j = 0, resume */
    EV_NONFINITE = 4, /* a non-finite value at the end of the block that began at k0 */
    EV_CHUNK = 5,     /* the chunk of steps is done (at a block boundary) */
    EV_HOOK = 6,      /* run the Python hook of op pc, then resume at pc + 1 */
    EV_REFILL = 7     /* op pc's noise stream has no row left: refill it, then resume at pc */
};

typedef struct {
    int64_t kind;
    int64_t owner;        /* index of the Python callable this op belongs to (in its phase) */
    int64_t n;            /* entries of idx / off */
    int64_t nvr;          /* value references */
    int64_t nbuf;         /* values moved by the FMI call (FMI 3.0 nValues) */
    int64_t status;       /* result: the failing status */
    int64_t flag;         /* result: terminateSimulation (FMI 3.0) */
    int64_t slot;         /* signal written by a source */
    void *fn;             /* the FMI or CasADi function */
    void *inst;           /* the FMU instance */
    const unsigned int *vr;
    double *buf;          /* the FMU side of a get / set */
    const int64_t *idx;   /* signal positions */
    const int64_t *off;   /* positions in buf */
    double a, b, c, d;    /* source parameters; d: FMI 3.0 lastSuccessfulTime */
    /* filter */
    const double **arg[2]; /* arguments from state copy 0 / 1 */
    double **res[2];
    long long *iw;
    double *w;
    double *ub, *yb;      /* the step's u and y inputs */
    double *uprev;        /* the input held from the previous instant */
    const int64_t *yidx;  /* measurement signals */
    int64_t ny, nu, nx, nup; /* nup: upper covariance entries in the summary */
    int64_t *cur;         /* [0]: current state copy, [1]: step count, [2]: started, [3]: stepped now */
    const double *status_out; /* the step's status output */
    const double *x[2], *P[2]; const double *nis;
    double *out;          /* summary destination (values + first output) */
    const int64_t *uidx;  /* input signals held by the update */
    const int64_t *upi, *upj; /* upper covariance entries */
} op_t;

typedef struct pool pool_t;

typedef struct {
    /* fixed for the run */
    double t0, h;
    int64_t n, m, L, cap, ncols, nint, nsig, block;
    double *values;
    int64_t *integers;
    double *buf;          /* record rows: cap x ncols */
    int64_t *ibuf;        /* integer record rows: cap x nint */
    const int64_t *sel;   /* recorded signals */
    const int64_t *isel;  /* recorded integer signals */
    const int64_t *pattern;   /* k % L -> pattern */
    const int64_t *out_start, *out_len, *upd_start, *upd_len; /* per pattern, into ops */
    op_t *ops;
    /* resumable state */
    int64_t k, phase, pc, j, jb, k0, kstop;
    int64_t at;           /* the op an EV_PY / EV_FAIL event is about (index into ops) */
    /* parallel stepping (set by Python between returns) */
    pool_t *pool;         /* NULL: every op on the calling thread */
    const int64_t *lane;  /* per op: its thread in a parallel segment, -1 outside one */
    const int64_t *seg;   /* per op: the ops of the parallel segment that begins there, else 0 */
    int64_t *fail_at;     /* per thread: its failing op in the last segment, -1 none */
    double *cost;         /* per op: wall seconds spent in it in segments (while timing) */
    double seg_time;      /* wall seconds spent in segments (while timing) */
    int64_t timing;       /* measure cost and seg_time */
} kstate_t;

static int finite_rows(const double *buf, int64_t ncols, int64_t lo, int64_t hi) {
    for (int64_t i = lo * ncols; i < hi * ncols; i++)
        if (!isfinite(buf[i])) return 0;
    return 1;
}

static int block_finite(kstate_t *s) {
    for (int64_t i = 0; i < s->nsig; i++)
        if (!isfinite(s->values[i])) return 0;
    if (s->j >= s->jb) return finite_rows(s->buf, s->ncols, s->jb, s->j);
    return finite_rows(s->buf, s->ncols, s->jb, s->cap) && finite_rows(s->buf, s->ncols, 0, s->j);
}

/* The FMI get or set of op (FMI 2.0 Real or, with its nValues nbuf >= 0, FMI 3.0 Float64):
 * its status. */
static int transfer(op_t *o) {
    return o->nbuf < 0 ? ((fmi2_xfer_t)o->fn)(o->inst, o->vr, (size_t)o->nvr, o->buf)
                       : ((fmi3_xfer_t)o->fn)(o->inst, o->vr, (size_t)o->nvr, o->buf, (size_t)o->nbuf);
}

/* Run op; 0: go on, else the event. */
static int run_op(kstate_t *s, op_t *o, double t) {
    double *v = s->values;
    int st;
    switch (o->kind) {
    case OP_PY:
        return EV_PY;
    case OP_GET:
        st = transfer(o);
        if (st > 1) { o->status = st; return EV_FAIL; }
        for (int64_t i = 0; i < o->n; i++) v[o->idx[i]] = o->buf[o->off[i]];
        return 0;
    case OP_SET:
        for (int64_t i = 0; i < o->n; i++) o->buf[o->off[i]] = v[o->idx[i]];
        st = transfer(o);
        if (st > 1) { o->status = st; return EV_FAIL; }
        return 0;
    case OP_STEP1:
        st = ((fmi1_step_t)o->fn)(o->inst, t, o->a, 1);
        if (st > 1) { o->status = st; return EV_FAIL; }
        return 0;
    case OP_STEP2:
        st = ((fmi2_step_t)o->fn)(o->inst, t, o->a, 1);
        if (st > 1) { o->status = st; return EV_FAIL; }
        return 0;
    case OP_STEP3: {
        bool ev = false, term = false, early = false;
        double last = 0.0;
        st = ((fmi3_step_t)o->fn)(o->inst, t, o->a, true, &ev, &term, &early, &last);
        if (st > 1 || term) { o->status = st; o->flag = term; o->d = last; return EV_FAIL; }
        return 0;
    }
    case OP_CONST:
        v[o->slot] = o->a;
        return 0;
    case OP_SWITCH:
        v[o->slot] = t >= o->a ? o->c : o->b;
        return 0;
    case OP_FILTER: {
        int64_t c = o->cur[0];
        o->cur[3] = 0;
        if (o->cur[2]) {
            for (int64_t i = 0; i < o->nu; i++) o->ub[i] = o->uprev[i];
            for (int64_t i = 0; i < o->ny; i++) o->yb[i] = v[o->yidx[i]];
            ((casadi_fn_t)o->fn)(o->arg[c], o->res[c], o->iw, o->w, 0);
            if (o->status_out[0] != 0.0) { o->status = 1; return EV_FAIL; }
            c ^= 1;
            o->cur[0] = c;
            o->cur[1] += 1;
            o->cur[3] = 1;
        }
        return 0;
    }
    case OP_SUMMARY: {
        int64_t c = o->cur[0];
        {
            const double *x = o->x[c], *P = o->P[c];
            int64_t nx = o->nx;
            double *out = o->out;
            for (int64_t i = 0; i < nx; i++) out[i] = x[i];
            for (int64_t i = 0; i < nx; i++) out[nx + i] = P[i + i * nx];
            for (int64_t q = 0; q < o->nup; q++) out[2 * nx + q] = P[o->upi[q] + o->upj[q] * nx];
            out[2 * nx + o->nup] = o->nis[0];
        }
        return 0;
    }
    case OP_HOOK:
        if (o->cur[3] && (o->buf == NULL || o->buf[0] != 0.0)) return EV_HOOK;
        return 0;
    case OP_NOISE: {      /* buf: rows of n values; cur: [row, rows]; w: [instant of the row] */
        if (t != o->w[0]) {
            if (o->cur[0] + 1 >= o->cur[1]) return EV_REFILL;
            o->cur[0] += 1;
            o->w[0] = t;
        }
        const double *z = o->buf + o->cur[0] * o->n;
        if (o->flag)      /* a sensor: y = u + bias + std z (ub: bias, yb: std, uidx: u) */
            for (int64_t i = 0; i < o->n; i++) v[o->idx[i]] = (v[o->uidx[i]] + o->ub[i]) + o->yb[i] * z[i];
        else
            for (int64_t i = 0; i < o->n; i++) v[o->idx[i]] = z[i];
        return 0;
    }
    case OP_PRBS: {       /* buf: the bits as 0.0 / 1.0, n of them */
        int64_t q = (int64_t)floor(t / o->a + 1e-9) % o->n;
        if (q < 0) q += o->n;
        v[o->slot] = o->b + (o->buf[q] != 0.0 ? o->c : -o->c);
        return 0;
    }
    case OP_RECORD: {     /* out: rows of [k, diag Q, diag R], n of them; iw: rows written; x, P: Q, R */
        if (!o->cur[3] || o->buf[0] == 0.0) return 0;
        if (o->iw[0] >= o->n) return EV_HOOK;       /* full: Python records (and grows the rows) */
        int64_t c = o->cur[0], nx = o->nx, ny = o->ny;
        double *row = o->out + o->iw[0] * (1 + nx + ny);
        row[0] = (double)o->cur[1];
        for (int64_t i = 0; i < nx; i++) row[1 + i] = o->x[c][i * (nx + 1)];
        for (int64_t i = 0; i < ny; i++) row[1 + nx + i] = o->P[c][i * (ny + 1)];
        o->iw[0] += 1;
        return 0;
    }
    case OP_HOLD:
        for (int64_t i = 0; i < o->nu; i++) o->uprev[i] = v[o->uidx[i]];
        o->cur[2] = 1;
        return 0;
    }
    return 0;
}

/* Wall seconds (CLOCK_MONOTONIC). The op timing uses it too: read from the vDSO it costs
 * some 25 ns, where a thread's CPU clock (CLOCK_THREAD_CPUTIME_ID) is a system call of some
 * 550 ns (measured on a 2-core virtual machine), which swamped the cost of cheap FMU steps. */
static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---------------------------------------------------------------- the thread pool */
#define MAX_THREADS 64
#define SPIN_SECONDS 50e-6
#define ALT_STACK (1 << 16)

struct pool {
    int64_t n;                    /* threads, the caller (thread 0) included */
    pthread_t tid[MAX_THREADS];
    kstate_t *s;                  /* the segment being run: ops [first, first + count) at t */
    int64_t first, count;
    double t;
    int gen, pending, quit;       /* segments published; threads still running one; end */
    int idle_workers, idle_caller; /* threads asleep on go / on done */
    pthread_mutex_t mu;
    pthread_cond_t go, done;
};

typedef struct { pool_t *p; int64_t me; } worker_arg_t;

static void relax(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

/* Wait until *word differs from old: spin for SPIN_SECONDS, then sleep on cv (idle counts
 * the sleepers, so that the other side takes the mutex only when someone sleeps). */
static void wait_change(pool_t *p, int *word, int old, pthread_cond_t *cv, int *idle) {
    double until = now() + SPIN_SECONDS;
    for (int i = 0; __atomic_load_n(word, __ATOMIC_ACQUIRE) == old; i++) {
        relax();
        if ((i & 63) == 63 && now() > until) {
            pthread_mutex_lock(&p->mu);
            __atomic_add_fetch(idle, 1, __ATOMIC_SEQ_CST);
            while (__atomic_load_n(word, __ATOMIC_SEQ_CST) == old) pthread_cond_wait(cv, &p->mu);
            __atomic_sub_fetch(idle, 1, __ATOMIC_SEQ_CST);
            pthread_mutex_unlock(&p->mu);
            return;
        }
    }
}

/* Wake the sleepers of cv (after the word they wait on changed), if any. */
static void wake(pool_t *p, pthread_cond_t *cv, int *idle) {
    if (__atomic_load_n(idle, __ATOMIC_SEQ_CST) == 0) return;
    pthread_mutex_lock(&p->mu);
    pthread_cond_broadcast(cv);
    pthread_mutex_unlock(&p->mu);
}

/* Thread me's ops of the published segment, in their order, up to its first failure
 * (while timing, each op's wall time added to its cost). */
static void run_lane(pool_t *p, int64_t me) {
    kstate_t *s = p->s;
    s->fail_at[me] = -1;
    for (int64_t i = p->first; i < p->first + p->count; i++) {
        if (s->lane[i] != me) continue;
        double c0 = s->timing ? now() : 0.0;
        int e = run_op(s, s->ops + i, p->t);
        if (s->timing) s->cost[i] += now() - c0;
        if (e) {
            s->fail_at[me] = i;
            return;
        }
    }
}

static void *worker(void *arg) {
    pool_t *p = ((worker_arg_t *)arg)->p;
    int64_t me = ((worker_arg_t *)arg)->me;
    free(arg);
#if defined(__linux__)
    prctl(PR_SET_NAME, "cosim-step");        /* seen in top, a debugger, /proc */
#endif
    sigset_t all;                 /* asynchronous signals (Ctrl-C) go to the caller's thread */
    sigfillset(&all);
    int synchronous[] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGTRAP, SIGSYS};
    for (size_t i = 0; i < sizeof synchronous / sizeof synchronous[0]; i++) sigdelset(&all, synchronous[i]);
    pthread_sigmask(SIG_BLOCK, &all, NULL);
    stack_t ss = {0};             /* the crash guard's handler runs on it, also for a stack overflow */
    ss.ss_sp = malloc(ALT_STACK);
    ss.ss_size = ALT_STACK;
    if (ss.ss_sp) sigaltstack(&ss, NULL);
    for (int seen = 0;;) {
        wait_change(p, &p->gen, seen, &p->go, &p->idle_workers);
        seen = __atomic_load_n(&p->gen, __ATOMIC_ACQUIRE);
        if (p->quit) break;
        run_lane(p, me);
        if (__atomic_sub_fetch(&p->pending, 1, __ATOMIC_SEQ_CST) == 0) wake(p, &p->done, &p->idle_caller);
    }
    if (ss.ss_sp) {
        ss.ss_flags = SS_DISABLE;
        sigaltstack(&ss, NULL);
        free(ss.ss_sp);
    }
    return NULL;
}

void kernel_pool_stop(pool_t *p);

/* A pool of n threads (the caller and n - 1 workers), or NULL (n out of range, no thread). */
pool_t *kernel_pool_start(int64_t n) {
    if (n < 2 || n > MAX_THREADS) return NULL;
    pool_t *p = calloc(1, sizeof(pool_t));
    if (!p) return NULL;
    pthread_mutex_init(&p->mu, NULL);
    pthread_cond_init(&p->go, NULL);
    pthread_cond_init(&p->done, NULL);
    p->n = 1;
    for (int64_t me = 1; me < n; me++) {
        worker_arg_t *arg = malloc(sizeof(worker_arg_t));
        if (!arg) break;
        arg->p = p;
        arg->me = me;
        if (pthread_create(&p->tid[me], NULL, worker, arg) != 0) {
            free(arg);
            break;
        }
        p->n = me + 1;
    }
    if (p->n < n) {
        kernel_pool_stop(p);
        return NULL;
    }
    return p;
}

/* End and join every worker, free the pool. */
void kernel_pool_stop(pool_t *p) {
    if (!p) return;
    p->quit = 1;
    __atomic_add_fetch(&p->gen, 1, __ATOMIC_SEQ_CST);
    pthread_mutex_lock(&p->mu);
    pthread_cond_broadcast(&p->go);
    pthread_mutex_unlock(&p->mu);
    for (int64_t me = 1; me < p->n; me++) pthread_join(p->tid[me], NULL);
    pthread_mutex_destroy(&p->mu);
    pthread_cond_destroy(&p->go);
    pthread_cond_destroy(&p->done);
    free(p);
}

/* Run the parallel segment of ops [first, first + count) at t: the first failing op in
 * the serial order, or -1. */
static int64_t run_segment(kstate_t *s, int64_t first, int64_t count, double t) {
    pool_t *p = s->pool;
    p->s = s;
    p->first = first;
    p->count = count;
    p->t = t;
    __atomic_store_n(&p->pending, (int)(p->n - 1), __ATOMIC_RELAXED);
    __atomic_add_fetch(&p->gen, 1, __ATOMIC_SEQ_CST);        /* publishes the segment */
    wake(p, &p->go, &p->idle_workers);
    run_lane(p, 0);
    for (int left; (left = __atomic_load_n(&p->pending, __ATOMIC_SEQ_CST)) != 0;)
        wait_change(p, &p->pending, left, &p->done, &p->idle_caller);
    int64_t at = -1;
    for (int64_t me = 0; me < p->n; me++)
        if (s->fail_at[me] >= 0 && (at < 0 || s->fail_at[me] < at)) at = s->fail_at[me];
    return at;
}

/* ---------------------------------------------------------------- the loop */

/* Run the ops [start, start + len) of the instant t from s->pc on: 0 when all ran, else the
 * event (s->at: the op it is about; s->pc stays on it, to resume there). With a pool, a
 * parallel segment runs on its threads (while timing, its wall time added to seg_time). */
static int run_ops(kstate_t *s, int64_t start, int64_t len, double t) {
    while (s->pc < len) {
        int64_t i = start + s->pc;
        if (s->pool && s->seg[i] > 0) {
            double c0 = s->timing ? now() : 0.0;
            int64_t at = run_segment(s, i, s->seg[i], t);
            if (s->timing) s->seg_time += now() - c0;
            if (at >= 0) {
                s->at = at;
                s->pc = at - start;
                return EV_FAIL;
            }
            s->pc += s->seg[i];
            continue;
        }
        int e = run_op(s, s->ops + i, t);
        if (e) { s->at = i; return e; }
        s->pc++;
    }
    return 0;
}

/* Run from the saved state until an event; the state says where to resume. */
int kernel_run(kstate_t *s) {
    for (;;) {
        if (s->phase == 0 && s->pc == 0) {
            if (s->k > s->k0 && (s->k - s->k0) % s->block == 0) {   /* a block ended */
                if (!block_finite(s)) return EV_NONFINITE;
                s->k0 = s->k;
                s->jb = s->j;
                if (s->k >= s->kstop) return EV_CHUNK;
            }
        }
        int64_t p = s->pattern[s->k % s->L];
        double t = s->t0 + (double)s->k * s->h;
        if (s->phase == 0) {
            int e = run_ops(s, s->out_start[p], s->out_len[p], t);
            if (e) return e;
            s->phase = 1;
            s->pc = 0;
        }
        if (s->phase == 1) {
            s->phase = 2;
            if (s->k % s->m == 0) {
                double *row = s->buf + s->j * s->ncols;
                for (int64_t c = 0; c < s->ncols; c++) row[c] = s->values[s->sel[c]];
                if (s->nint) {
                    int64_t *irow = s->ibuf + s->j * s->nint;
                    for (int64_t c = 0; c < s->nint; c++) irow[c] = s->integers[s->isel[c]];
                }
                s->j += 1;
                if (s->j == s->cap) {
                    if (s->k == s->n) s->phase = 3;
                    return EV_FLUSH;
                }
            }
            if (s->k == s->n) { s->phase = 3; }
        }
        if (s->phase == 3) {                 /* the last instant: no update */
            if (!block_finite(s)) return EV_NONFINITE;
            return EV_DONE;
        }
        if (s->phase == 2) {
            if (s->k == s->n) { s->phase = 3; continue; }
            int e = run_ops(s, s->upd_start[p], s->upd_len[p], t);
            if (e) return e;
        }
        s->phase = 0;
        s->pc = 0;
        s->k += 1;
    }
}
