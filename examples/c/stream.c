/*
 * Online thresholds from C: load a calibration file, then decide each query of a
 * deployment similarity matrix (|DB| x |Q| .npy, float32 or float64) as if it arrived
 * from a camera, one push at a time, printing one JSON line per decision (the lines of
 * `qtvpr-cli stream --format jsonl`).
 *
 *     stream CAL.npz DEPLOY.npy [K PRECISION WINDOW MIN_WINDOW [GATE]]
 *
 * Each parameter left out or 0 takes the calibration file's value; GATE is "none",
 * "margin", "sequence" or "margin,sequence" (the file's when left out). A calibration
 * file of `qtvpr-cli calibrate --sequence L` decides each query on its causal
 * sequence-matched column: nothing here changes for it.
 * Build: cc -Iinclude examples/c/stream.c -Ltarget/release -lqtvpr -o stream
 */
#include <stdio.h>
#include <stdlib.h>

#include "example_io.h"
#include "qtvpr.h"

int main(int argc, char **argv) {
    qtvpr_calibration *cal = NULL;
    qtvpr_online *online = NULL;
    npy_matrix s = {0};
    void *column = NULL;
    int status = 1;
    size_t j;

    qtvpr_online_options opts;

    if (argc != 3 && argc != 7 && argc != 8) {
        fprintf(stderr, "usage: %s CAL.npz DEPLOY.npy [K PRECISION WINDOW MIN_WINDOW [GATE]]\n", argv[0]);
        return 2;
    }
    if (!(cal = qtvpr_calibration_load(argv[1]))) goto error;
    qtvpr_online_options_init(&opts); /* every parameter the file's */
    if (argc >= 7) {
        opts.k = strtoul(argv[3], NULL, 10);
        opts.precision = strtod(argv[4], NULL);
        opts.window = strtoul(argv[5], NULL, 10);
        opts.min_window = strtoul(argv[6], NULL, 10);
    }
    if (argc == 8) opts.gate = argv[7];
    if (!(online = qtvpr_online_new_with(cal, &opts))) goto error;
    if (npy_read(argv[2], &s) != 0) goto done;
    if (!(column = malloc(s.rows * s.itemsize))) goto done;

    for (j = 0; j < s.cols; j++) {
        qtvpr_decision d;
        int rc;
        npy_column(&s, j, column); /* query j's scores against the database */
        rc = s.itemsize == 4 ? qtvpr_online_push_f32(online, (const float *)column, s.rows, &d)
                             : qtvpr_online_push_f64(online, (const double *)column, s.rows, &d);
        if (rc != QTVPR_OK) goto error;
        print_decision(&d);
    }
    status = 0;
    goto done;
error:
    fprintf(stderr, "error: %s\n", qtvpr_last_error());
done:
    free(column);
    free(s.data);
    qtvpr_online_free(online);
    qtvpr_calibration_free(cal);
    return status;
}
