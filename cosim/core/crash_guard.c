/* The crash guard of the co-simulation master: when the code of an FMU that runs in the
 * master's own process (not isolated) kills it with a fatal signal, say which component's
 * FMU, which FMI function and which time, tell the user how to isolate it, start the
 * salvage program (the rows streamed so far become the partial result file; the run's
 * temporary folders are removed), then hand the signal to whatever handled it before (the
 * process ends as it would have).
 *
 * The handler uses only what a fatal-signal handler can: write(2), fork(2), execve(2),
 * waitpid(2), sigaction(2); backtrace(3) is warmed up at installation (its first call may
 * load the unwinder) and dladdr(3) reads the loader's tables, as crash reporters do.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <execinfo.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#define MAX_LIBS 512
#define NAME_LEN 200
#define MAX_ARGS 256
#define ARG_STORE 65536
#define N_SIGNALS 5

extern char **environ;

static struct { void *base; char name[NAME_LEN]; } libs[MAX_LIBS];
static volatile int64_t n_libs;
static const volatile int64_t *step_at;   /* the base step being computed, or NULL */
static double t_start, t_step;
static char *salvage_argv[MAX_ARGS + 1];
static char salvage_store[ARG_STORE];
static const int watched[N_SIGNALS] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT};
static const char *const signal_names[N_SIGNALS] = {"SIGSEGV", "SIGBUS", "SIGILL", "SIGFPE", "SIGABRT"};
static struct sigaction previous[N_SIGNALS];
static int installed;
static char alt_stack[1 << 16];

static void say(const char *s) {
    size_t n = strlen(s);
    while (n > 0) {
        ssize_t w = write(2, s, n);
        if (w <= 0) return;
        s += w;
        n -= (size_t)w;
    }
}

static int find(const void *base) {
    for (int64_t i = 0; i < n_libs; i++)
        if (libs[i].base == base) return (int)i;
    return -1;
}

static void handler(int sig, siginfo_t *info, void *context) {
    (void)info;
    (void)context;
    int which = 0;
    while (which < N_SIGNALS - 1 && watched[which] != sig) which++;
    void *frames[128];
    int n = backtrace(frames, 128);
    int lib = -1;
    const char *call = NULL;
    for (int i = 0; i < n; i++) {
        Dl_info d;
        /* a return address may be the first byte after its call: look one byte back */
        if (!frames[i] || !dladdr((char *)frames[i] - 1, &d)) {
            if (lib >= 0) break;
            continue;
        }
        int j = find(d.dli_fbase);
        if (j >= 0 && (lib < 0 || lib == j)) {
            lib = j;                      /* the outermost frame in the FMU: the call made into it */
            call = d.dli_sname;
        } else if (lib >= 0) {
            break;
        }
    }
    if (lib >= 0) {
        char line[1024];
        char when[96] = "while it was set up or shut down";
        if (step_at) snprintf(when, sizeof when, "at t = %.9g s", t_start + (double)(*step_at) * t_step);
        snprintf(line, sizeof line,
                 "\nerror: the FMU of component %s crashed the process (%s) in %s %s. It runs in the "
                 "master's own process; set isolate = true for that component (FMUComponent(..., "
                 "isolate=True)) to run it in a process of its own: a crash is then a named error "
                 "and the run keeps its results.\n",
                 libs[lib].name, signal_names[which], call ? call : "its code", when);
        say(line);
        if (salvage_argv[0]) {
            pid_t pid = fork();
            if (pid == 0) {
                execve(salvage_argv[0], salvage_argv, environ);
                _exit(127);
            }
            if (pid > 0) {
                int status;
                while (waitpid(pid, &status, 0) < 0) {
                }
            }
        }
    }
    /* hand the signal on: the previous handler (or the default action) sees it next */
    sigaction(sig, &previous[which], NULL);
    raise(sig);
}

/* Install the handler for the fatal signals (once per process). 0, or -1. */
int guard_install(void) {
    if (installed) return 0;
    void *warm[4];
    backtrace(warm, 4);
    stack_t ss;
    memset(&ss, 0, sizeof ss);
    ss.ss_sp = alt_stack;
    ss.ss_size = sizeof alt_stack;
    stack_t old;
    if (sigaltstack(NULL, &old) == 0 && (old.ss_flags & SS_DISABLE)) sigaltstack(&ss, NULL);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_sigaction = handler;
    sa.sa_flags = SA_SIGINFO | SA_ONSTACK;
    sigemptyset(&sa.sa_mask);
    for (int i = 0; i < N_SIGNALS; i++)
        if (sigaction(watched[i], &sa, &previous[i]) != 0) return -1;
    installed = 1;
    return 0;
}

/* The FMU library holding the function at fn belongs to component name. Its entry (for
 * guard_unregister), or -1 (unknown address, table full). */
int guard_register(const void *fn, const char *name) {
    Dl_info d;
    if (!fn || !name || !dladdr(fn, &d) || !d.dli_fbase) return -1;
    int j = find(d.dli_fbase);
    if (j < 0) j = find(NULL);                /* a freed entry */
    if (j < 0) {
        if (n_libs >= MAX_LIBS) return -1;
        j = (int)n_libs;
    }
    if (libs[j].base != d.dli_fbase) libs[j].name[0] = '\0';
    char quoted[NAME_LEN];
    snprintf(quoted, sizeof quoted, "'%s'", name);
    if (strstr(libs[j].name, quoted) == NULL) {
        size_t used = strlen(libs[j].name);
        snprintf(libs[j].name + used, NAME_LEN - used, "%s%s", used ? " or " : "", quoted);
    }
    libs[j].base = d.dli_fbase;
    if (j == n_libs) n_libs++;
    return j;
}

/* Forget entry j (its library was unloaded). */
void guard_unregister(int j) {
    if (j < 0 || j >= n_libs) return;
    libs[j].base = NULL;
    libs[j].name[0] = '\0';
}

/* The time of a crash is t0 + (*step) * h; step NULL: no run in progress. */
void guard_time(const int64_t *step, double t0, double h) {
    t_start = t0;
    t_step = h;
    step_at = step;
}

/* The salvage program's argument vector (argv[0] a path), or n = 0 for none. 0, or -1. */
int guard_salvage(const char *const *argv, int n) {
    salvage_argv[0] = NULL;
    if (n <= 0) return 0;
    if (n > MAX_ARGS) return -1;
    size_t used = 0;
    for (int i = 0; i < n; i++) {
        size_t len = strlen(argv[i]) + 1;
        if (used + len > ARG_STORE) {
            salvage_argv[0] = NULL;
            return -1;
        }
        memcpy(salvage_store + used, argv[i], len);
        salvage_argv[i + 1] = NULL;
        salvage_argv[i] = salvage_store + used;
        used += len;
    }
    salvage_argv[n] = NULL;
    return 0;
}
