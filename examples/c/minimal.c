/* The example of docs/deployment.md and crates/qtvpr-capi/README.md: decide each query
 * read from stdin, its n_db float32 scores after the previous query's (raw,
 * little-endian).  Usage: minimal cal.npz < scores.f32 */
#include <stdio.h>
#include <stdlib.h>
#include "qtvpr.h"

int main(int argc, char **argv) {
    qtvpr_calibration *cal = qtvpr_calibration_load(argc > 1 ? argv[1] : "cal.npz");
    qtvpr_online *o = cal ? qtvpr_online_new(cal, 0, 0.0, 0, 0) : NULL; /* 0: the file's value */
    if (!o) {
        fprintf(stderr, "error: %s\n", qtvpr_last_error()); /* names the file and the problem */
        qtvpr_calibration_free(cal);
        return 1;
    }
    size_t n_db = qtvpr_calibration_db_size(cal);
    float *scores = (float *)malloc(n_db * sizeof *scores);
    qtvpr_decision d;
    int rc = QTVPR_OK;
    while (rc == QTVPR_OK && fread(scores, sizeof *scores, n_db, stdin) == n_db)
        if ((rc = qtvpr_online_push_f32(o, scores, n_db, &d)) == QTVPR_OK)
            printf("query %zu: best match %zu (score %.3f) %s at threshold %.3f\n", d.query, d.best,
                   d.score, d.accept ? "accepted" : "rejected", d.threshold);
    if (rc != QTVPR_OK) fprintf(stderr, "error: %s\n", qtvpr_last_error());
    free(scores);
    qtvpr_online_free(o);
    qtvpr_calibration_free(cal);
    return rc;
}
