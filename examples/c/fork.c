/*
 * A process that forks after using qtvpr has a working library in the child.
 *
 *     fork CAL.npz DEPLOY.npy
 *
 * The parent sizes the library's thread pool (qtvpr_set_threads), pushes the first 50
 * queries of DEPLOY.npy into one state and the first 60 into another, then forks. The
 * child pushes queries 50..59 into its copy of the first state, and streams the first
 * 60 through a calibration it loads itself; every decision must equal the parent's.
 * The parent waits at most 30 s (alarm), then kills the child and fails: before the
 * library rebuilt its pool in a forked child, the child's first push waited forever
 * for threads that exist only in the parent.
 *
 * Exit status 0 when the child's decisions equal the parent's, 1 otherwise.
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include "example_io.h"
#include "qtvpr.h"

#define SPLIT 50
#define QUERIES 60
#define TIMEOUT 30

static volatile sig_atomic_t timed_out = 0;

static void on_alarm(int sig) {
    (void)sig;
    timed_out = 1;
}

/* Push columns first..last-1 of s into o; decisions into out (may be NULL). 0 or -1. */
static int push(qtvpr_online *o, const npy_matrix *s, void *column, size_t first, size_t last,
                qtvpr_decision *out) {
    size_t j;
    for (j = first; j < last; j++) {
        qtvpr_decision d;
        int rc;
        npy_column(s, j, column);
        rc = s->itemsize == 4 ? qtvpr_online_push_f32(o, (const float *)column, s->rows, &d)
                              : qtvpr_online_push_f64(o, (const double *)column, s->rows, &d);
        if (rc != QTVPR_OK) {
            fprintf(stderr, "fork: push %zu: %s\n", j, qtvpr_last_error());
            return -1;
        }
        if (out) out[j - first] = d;
    }
    return 0;
}

static int same(const qtvpr_decision *a, const qtvpr_decision *b, size_t n) {
    size_t i;
    for (i = 0; i < n; i++) {
        if (a[i].query != b[i].query || a[i].threshold != b[i].threshold || a[i].quantile != b[i].quantile ||
            a[i].best != b[i].best || a[i].accept != b[i].accept || a[i].accepted != b[i].accepted ||
            a[i].weight != b[i].weight || a[i].query_quantile != b[i].query_quantile) {
            fprintf(stderr, "fork: query %zu: threshold %.17g in the child, %.17g in the parent\n", a[i].query,
                    a[i].threshold, b[i].threshold);
            return 0;
        }
    }
    return 1;
}

/* The child: continue `half` and stream again from a calibration it loads. 0 or 1. */
static int child(const char *cal_path, qtvpr_online *half, const npy_matrix *s, void *column,
                 const qtvpr_decision *want) {
    qtvpr_decision got[QUERIES];
    qtvpr_calibration *cal;
    qtvpr_online *o;
    int ok;
    if (push(half, s, column, SPLIT, QUERIES, got) != 0 || !same(got, want + SPLIT, QUERIES - SPLIT)) return 1;
    if (!(cal = qtvpr_calibration_load(cal_path))) {
        fprintf(stderr, "fork: %s\n", qtvpr_last_error());
        return 1;
    }
    o = qtvpr_online_new(cal, 0, 0.0, 0, 0);
    qtvpr_calibration_free(cal);
    if (!o) {
        fprintf(stderr, "fork: %s\n", qtvpr_last_error());
        return 1;
    }
    ok = push(o, s, column, 0, QUERIES, got) == 0 && same(got, want, QUERIES);
    qtvpr_online_free(o);
    return ok ? 0 : 1;
}

int main(int argc, char **argv) {
    qtvpr_calibration *cal = NULL;
    qtvpr_online *half = NULL, *full = NULL;
    qtvpr_decision want[QUERIES];
    npy_matrix s = {0};
    void *column = NULL;
    int status = 1, wstatus = 0;
    struct sigaction sa;
    pid_t pid;

    if (argc != 3) {
        fprintf(stderr, "usage: %s CAL.npz DEPLOY.npy\n", argv[0]);
        return 2;
    }
    /* The pool's size: 0 threads is an error, 2 is kept by the child. */
    if (qtvpr_set_threads(0) != QTVPR_ERR_PARAM || qtvpr_last_error_code() != QTVPR_ERR_PARAM) {
        fprintf(stderr, "fork: qtvpr_set_threads(0) is not QTVPR_ERR_PARAM\n");
        return 1;
    }
    printf("qtvpr_set_threads(0): %s\n", qtvpr_last_error());
    if (qtvpr_set_threads(2) != QTVPR_OK) goto error;
    if (!(cal = qtvpr_calibration_load(argv[1]))) goto error;
    if (!(half = qtvpr_online_new(cal, 0, 0.0, 0, 0))) goto error;
    if (!(full = qtvpr_online_new(cal, 0, 0.0, 0, 0))) goto error;
    if (npy_read(argv[2], &s) != 0) goto done;
    if (s.cols < QUERIES) {
        fprintf(stderr, "fork: %s has fewer than %d queries\n", argv[2], QUERIES);
        goto done;
    }
    if (!(column = malloc(s.rows * s.itemsize))) goto done;
    /* The parent uses the library (and its thread pool) before it forks. */
    if (push(half, &s, column, 0, SPLIT, NULL) != 0 || push(full, &s, column, 0, QUERIES, want) != 0) goto done;

    fflush(stdout);
    pid = fork();
    if (pid < 0) {
        perror("fork");
        goto done;
    }
    if (pid == 0) _exit(child(argv[1], half, &s, column, want));

    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_alarm; /* no SA_RESTART: the alarm interrupts waitpid */
    sigemptyset(&sa.sa_mask);
    sigaction(SIGALRM, &sa, NULL);
    alarm(TIMEOUT);
    while (waitpid(pid, &wstatus, 0) < 0) {
        if (errno != EINTR) {
            perror("waitpid");
            goto done;
        }
        if (timed_out) {
            kill(pid, SIGKILL);
            waitpid(pid, &wstatus, 0);
            fprintf(stderr, "fork: the child hung (no result after %d s)\n", TIMEOUT);
            goto done;
        }
    }
    alarm(0);
    if (!WIFEXITED(wstatus) || WEXITSTATUS(wstatus) != 0) {
        fprintf(stderr, "fork: the child failed (status %#x)\n", (unsigned)wstatus);
        goto done;
    }
    printf("fork: the child's %d decisions equal the parent's; the last:\n", QUERIES);
    print_decision(&want[QUERIES - 1]);
    status = 0;
    goto done;
error:
    fprintf(stderr, "fork: %s\n", qtvpr_last_error());
done:
    free(column);
    free(s.data);
    qtvpr_online_free(half);
    qtvpr_online_free(full);
    qtvpr_calibration_free(cal);
    return status;
}
