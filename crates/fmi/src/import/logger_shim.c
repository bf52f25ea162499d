/* The FMI 2.0 logger is a C variadic function (printf-style). Rust cannot define one on
 * stable, so this shim formats the message and hands the finished text to a sink that
 * the importer passes as the component environment. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

typedef void (*twinbench_sink_fn)(void *ctx, const char *instance, int status,
                                  const char *category, const char *message);

typedef struct {
    twinbench_sink_fn sink;
    void *ctx;
} twinbench_log_env;

void twinbench_fmi2_logger(void *env, const char *instance, int status,
                           const char *category, const char *message, ...) {
    twinbench_log_env *e = (twinbench_log_env *)env;
    if (e == NULL || e->sink == NULL) return;
    if (message == NULL) {
        e->sink(e->ctx, instance, status, category, "(NULL message)");
        return;
    }
    char buf[1024];
    va_list ap;
    va_start(ap, message);
    int n = vsnprintf(buf, sizeof buf, message, ap);
    va_end(ap);
    if (n < 0) {
        e->sink(e->ctx, instance, status, category, message);
    } else if ((size_t)n < sizeof buf) {
        e->sink(e->ctx, instance, status, category, buf);
    } else {
        char *big = (char *)malloc((size_t)n + 1);
        if (big == NULL) {
            e->sink(e->ctx, instance, status, category, buf);
            return;
        }
        va_start(ap, message);
        vsnprintf(big, (size_t)n + 1, message, ap);
        va_end(ap);
        e->sink(e->ctx, instance, status, category, big);
        free(big);
    }
}
