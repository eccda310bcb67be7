/*
 * The error paths of the C interface, from C: every documented code, the message it
 * sets, and that nothing crashes. Run by scripts/capi.sh (once under valgrind).
 *
 *     errors CAL.npz N_DB SCRATCH_DIR MULTI.npz
 *
 * CAL.npz is a valid single-matching calibration file over N_DB database images that
 * sets a window, MULTI.npz a multi-matching one;
 * SCRATCH_DIR is a writable directory for a corrupt file. Prints each failed check and
 * exits 1 if there is any.
 */
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "qtvpr.h"


static void *error_in_thread(void *arg) {
    (void)arg;
    CHECK(qtvpr_last_error() == NULL); /* a new thread has no last error */
    CHECK(qtvpr_calibration_db_size(NULL) == 0);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_calibration_db_size: cal is NULL", NULL);
    return NULL;
}

int main(int argc, char **argv) {
    char corrupt[4096], directory[4096];
    size_t n_db, i, idx[4];
    qtvpr_calibration *cal, *multi;
    qtvpr_online *o;
    qtvpr_decision d, untouched;
    double *scores;
    float *scores32;
    FILE *f;
    pthread_t thread;

    if (argc != 5) {
        fprintf(stderr, "usage: %s CAL.npz N_DB SCRATCH_DIR MULTI.npz\n", argv[0]);
        return 2;
    }
    n_db = strtoul(argv[2], NULL, 10);

    /* Loading: NULL, a missing file, a directory, a corrupt file. */
    CHECK(qtvpr_calibration_load(NULL) == NULL);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_calibration_load: path is NULL", NULL);
    snprintf(corrupt, sizeof corrupt, "%s/missing.npz", argv[3]);
    CHECK(qtvpr_calibration_load(corrupt) == NULL);
    EXPECT_ERROR(QTVPR_ERR_IO, "qtvpr_calibration_load: cannot read", corrupt);
    snprintf(directory, sizeof directory, "%s", argv[3]);
    CHECK(qtvpr_calibration_load(directory) == NULL);
    EXPECT_ERROR(QTVPR_ERR_IO, "cannot read", directory);
    snprintf(corrupt, sizeof corrupt, "%s/corrupt.npz", argv[3]);
    f = fopen(corrupt, "wb");
    CHECK(f != NULL);
    if (f) {
        fputs("PK\003\004 this is not a zip archive", f);
        fclose(f);
    }
    CHECK(qtvpr_calibration_load(corrupt) == NULL);
    EXPECT_ERROR(QTVPR_ERR_FILE, "qtvpr_calibration_load: ", corrupt);

    /* Queries on a NULL calibration. */
    CHECK(qtvpr_calibration_db_size(NULL) == 0);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_calibration_db_size: cal is NULL", NULL);
    CHECK(qtvpr_calibration_matching(NULL) == 0);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_calibration_matching: cal is NULL", NULL);
    CHECK(qtvpr_online_new(NULL, 0, 0.0, 0, 0) == NULL);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_online_new: cal is NULL", NULL);

    /* A valid file; success clears the last error. */
    cal = qtvpr_calibration_load(argv[1]);
    if (!cal) {
        fprintf(stderr, "cannot load %s: %s\n", argv[1], qtvpr_last_error());
        return 1;
    }
    EXPECT_OK();
    CHECK(qtvpr_calibration_db_size(cal) == n_db);
    CHECK(qtvpr_calibration_matching(cal) == QTVPR_SINGLE || qtvpr_calibration_matching(cal) == QTVPR_MULTI);

    /* Parameters out of range. */
    CHECK(qtvpr_online_new(cal, 0, 1.5, 0, 0) == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "qtvpr_online_new: precision must be in (0, 1], got 1.5", NULL);
    CHECK(qtvpr_online_new(cal, 0, -0.5, 0, 0) == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "precision", "-0.5");
    CHECK(qtvpr_online_new(cal, 0, NAN, 0, 0) == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "precision", NULL);
    CHECK(qtvpr_online_new(cal, 0, 0.0, 3, 4) == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "min window must be between 1 and the window (3), got 4", NULL);
    /* A window whose full state (window x n_db doubles) no allocation could hold is
       refused up front; the largest that could is accepted (it takes memory as queries
       arrive). k above the number of calibration queries is clipped, so SIZE_MAX is k. */
    CHECK(qtvpr_online_new(cal, 0, 0.0, SIZE_MAX, 0) == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "qtvpr_online_new: window", "too large");
    CHECK(qtvpr_online_new(cal, 0, 0.0, (size_t)PTRDIFF_MAX / 8 / n_db + 1, 0) == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "window", "more memory than can be allocated");
    o = qtvpr_online_new(cal, SIZE_MAX, 0.0, (size_t)PTRDIFF_MAX / 8 / n_db, 0);
    CHECK(o != NULL);
    EXPECT_OK();
    qtvpr_online_free(o);
    /* The gate: a name the core knows (NULL: the file's), and only where it applies. */
    CHECK(qtvpr_online_new_gate(cal, 0, 0.0, 3, 1, "ratio") == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM,
                 "qtvpr_online_new_gate: gate must be none, or one or more of margin, sequence joined by commas",
                 "unknown gate \"ratio\"");
    o = qtvpr_online_new_gate(cal, 0, 0.0, 3, 1, "margin");
    CHECK(o != NULL);
    EXPECT_OK();
    qtvpr_online_free(o);
    o = qtvpr_online_new_gate(cal, 0, 0.0, 3, 1, NULL);
    CHECK(o != NULL);
    qtvpr_online_free(o);
    multi = qtvpr_calibration_load(argv[4]);
    CHECK(multi != NULL && qtvpr_calibration_matching(multi) == QTVPR_MULTI);
    CHECK(qtvpr_online_new_gate(multi, 0, 0.0, 3, 1, "margin") == NULL);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "qtvpr_online_new_gate: gate margin needs single matching", NULL);
    qtvpr_calibration_free(multi);
    /* The thread pool cannot be empty. */
    CHECK(qtvpr_set_threads(0) == QTVPR_ERR_PARAM);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "qtvpr_set_threads: threads must be >= 1, got 0", NULL);
    /* Nor larger than 1024 threads: 2^40 is refused at once, before a thread starts. */
    CHECK(qtvpr_set_threads((size_t)1 << 40) == QTVPR_ERR_PARAM);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "qtvpr_set_threads: threads must be at most 1024, got 1099511627776", NULL);
    CHECK(qtvpr_online_new(cal, 0, 0.0, 3, 4) == NULL);

    /* qtvpr_version does not touch the last error. */
    CHECK(qtvpr_version() != NULL && strlen(qtvpr_version()) > 0);
    EXPECT_ERROR(QTVPR_ERR_PARAM, "min window", NULL);

    o = qtvpr_online_new(cal, 0, 0.0, 3, 1);
    CHECK(o != NULL);
    EXPECT_OK();
    /* The state keeps what it needs: the calibration may go first (valgrind checks it). */
    qtvpr_calibration_free(cal);
    EXPECT_OK();
    if (!o) return 1;

    scores = (double *)calloc(n_db + 1, sizeof *scores);
    scores32 = (float *)calloc(n_db + 1, sizeof *scores32);
    for (i = 0; i < n_db; i++) scores32[i] = (float)(scores[i] = (double)(i % 7) / 7.0);
    memset(&untouched, 0xab, sizeof untouched);

    /* Pushes that fail leave *out and the state unchanged. */
    d = untouched;
    CHECK(qtvpr_online_push_f64(NULL, scores, n_db, &d) == QTVPR_ERR_NULL);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_online_push_f64: o is NULL", NULL);
    CHECK(qtvpr_online_push_f64(o, NULL, n_db, &d) == QTVPR_ERR_NULL);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_online_push_f64: scores is NULL", NULL);
    CHECK(qtvpr_online_push_f32(o, scores32, n_db, NULL) == QTVPR_ERR_NULL);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_online_push_f32: out is NULL", NULL);
    CHECK(qtvpr_online_push_f64(o, scores, n_db - 1, &d) == QTVPR_ERR_SIZE);
    EXPECT_ERROR(QTVPR_ERR_SIZE, "qtvpr_online_push_f64: deployment query 0 has", "database images");
    CHECK(qtvpr_online_push_f32(o, scores32, n_db + 1, &d) == QTVPR_ERR_SIZE);
    EXPECT_ERROR(QTVPR_ERR_SIZE, "qtvpr_online_push_f32: deployment query 0 has", NULL);
    CHECK(qtvpr_online_push_f32(o, scores32, 0, &d) == QTVPR_ERR_SIZE);
    scores[n_db / 2] = NAN;
    CHECK(qtvpr_online_push_f64(o, scores, n_db, &d) == QTVPR_ERR_INPUT);
    EXPECT_ERROR(QTVPR_ERR_INPUT, "qtvpr_online_push_f64: ", "NaN");
    scores[n_db / 2] = INFINITY;
    CHECK(qtvpr_online_push_f64(o, scores, n_db, &d) == QTVPR_ERR_INPUT);
    EXPECT_ERROR(QTVPR_ERR_INPUT, "inf", NULL);
    scores[n_db / 2] = 0.5;
    CHECK(qtvpr_online_push_f64(o, (const double *)((const char *)scores + 1), n_db, &d) == QTVPR_ERR_INPUT);
    EXPECT_ERROR(QTVPR_ERR_INPUT, "is not aligned for double", NULL);
    CHECK(memcmp(&d, &untouched, sizeof d) == 0);

    /* Nothing was pushed: the next query is query 0, and the size query works. */
    CHECK(qtvpr_online_accepted(o, NULL, 0) == 0);
    EXPECT_OK();
    CHECK(qtvpr_online_push_f64(o, scores, n_db, &d) == QTVPR_OK);
    EXPECT_OK();
    CHECK(d.query == 0);
    CHECK(d.accept == (d.accepted > 0));
    CHECK(qtvpr_online_push_f32(o, scores32, n_db, &d) == QTVPR_OK);
    CHECK(d.query == 1);
    CHECK(qtvpr_online_accepted(o, NULL, 0) == d.accepted);
    CHECK(qtvpr_online_accepted(o, idx, 4) == d.accepted);
    for (i = 0; i < d.accepted && i < 4; i++) CHECK(scores32[idx[i]] >= d.threshold);

    /* qtvpr_online_accepted's errors. */
    CHECK(qtvpr_online_accepted(NULL, idx, 4) == 0);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_online_accepted: o is NULL", NULL);
    CHECK(qtvpr_online_accepted(o, NULL, 4) == 0);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_online_accepted: out is NULL", NULL);

    /* The last error is per thread. */
    CHECK(pthread_create(&thread, NULL, error_in_thread, NULL) == 0);
    CHECK(pthread_join(thread, NULL) == 0);
    EXPECT_ERROR(QTVPR_ERR_NULL, "qtvpr_online_accepted: out is NULL", NULL);

    /* Freeing NULL is a no-op. */
    qtvpr_online_free(NULL);
    qtvpr_calibration_free(NULL);
    EXPECT_OK();

    qtvpr_online_free(o);
    free(scores);
    free(scores32);
    if (failures) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("errors: all checks passed (qtvpr %s)\n", qtvpr_version());
    return 0;
}
