/*
 * Hostile calibration files from C (docs/semantics.md §10 "Files and
 * processes" and §12 integrity): qtvpr_calibration_load returns NULL with an error code
 * and a message naming the file (and the member) instead of hanging, aborting or
 * loading other values. Run by scripts/capi.sh, under `ulimit -v 1000000`.
 *
 *     hostile SCRATCH_DIR SMALL.npz CRC.npz BZIP2_BOMB.npz DEFLATE_BOMB.npz MANIFEST BIG.npz
 *
 * SMALL.npz is a valid calibration file that sets a window; CRC.npz is it with one bit
 * of its s member's data flipped; the bombs are made by scripts/capi_check.py (a few kB
 * whose s.npy expands to 1 GiB with bzip2; 40 MB deflated, its shape disagreeing with
 * gt). MANIFEST lists the hostile set of tests/hostile_npz.py (a file and a part of its
 * error a line, tab-separated: AES with and without its flag, other methods, ZipCrypto,
 * duplicates, bad CRCs, bombs, 1-D and 3-D shapes); BIG.npz is a valid calibration too
 * large for the address-space cap (left out under valgrind, which the cap does not
 * bind). SCRATCH_DIR is a writable directory for a FIFO and
 * the flipped files.
 *
 * Checks:
 * - a FIFO with no writer: NULL and QTVPR_ERR_IO at once (an alarm kills a hang);
 * - CRC.npz: NULL, QTVPR_ERR_FILE, a message naming the file, the member s and CRC-32;
 * - every byte of SMALL.npz flipped in turn (one bit, then all eight): NULL with
 *   QTVPR_ERR_FILE and the file's name, or a calibration whose decisions are
 *   bit-identical to SMALL.npz's;
 * - the bombs: NULL with QTVPR_ERR_FILE naming the member, in under a second, with
 *   less than 100 MB of peak RSS;
 * - every file of MANIFEST: NULL, QTVPR_ERR_FILE, and its message names the file and
 *   holds the manifest's part;
 * - BIG.npz: NULL and QTVPR_ERR_MEMORY ("cannot allocate"), never an abort.
 * Prints each failed check and exits 1 if there is any.
 */
#define _POSIX_C_SOURCE 200809L

#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "check.h"
#include "qtvpr.h"


static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static long peak_rss_kib(void) {
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss;
}

/* A deployment traverse: N_QUERIES columns of n_db scores, fixed (a small LCG). */
#define N_QUERIES 25
static double *deployment(size_t n_db) {
    double *s = (double *)malloc(N_QUERIES * n_db * sizeof *s);
    uint64_t x = 11;
    size_t i;
    for (i = 0; s && i < N_QUERIES * n_db; i++) {
        x = x * 6364136223846793005ULL + 1442695040888963407ULL;
        s[i] = (double)((x >> 33) % 40) / 40.0 - 0.3;
    }
    return s;
}

/* The decisions of cal, at its file's parameters, on the deployment traverse s. */
static int decide(const qtvpr_calibration *cal, const double *s, size_t n_db, qtvpr_decision *out) {
    qtvpr_online *o = qtvpr_online_new(cal, 0, 0.0, 0, 0);
    size_t j;
    if (!o) return 0;
    for (j = 0; j < N_QUERIES; j++) {
        if (qtvpr_online_push_f64(o, s + j * n_db, n_db, &out[j]) != QTVPR_OK) {
            qtvpr_online_free(o);
            return 0;
        }
    }
    qtvpr_online_free(o);
    return 1;
}

/* Bit-identical decisions. */
static int same(const qtvpr_decision *a, const qtvpr_decision *b) {
    size_t j;
    for (j = 0; j < N_QUERIES; j++) {
        if (a[j].query != b[j].query || a[j].best != b[j].best || a[j].accept != b[j].accept ||
            a[j].accepted != b[j].accepted || memcmp(&a[j].threshold, &b[j].threshold, sizeof(double)) ||
            memcmp(&a[j].quantile, &b[j].quantile, sizeof(double)) ||
            memcmp(&a[j].score, &b[j].score, sizeof(double)) ||
            memcmp(&a[j].query_quantile, &b[j].query_quantile, sizeof(double)) ||
            memcmp(&a[j].weight, &b[j].weight, sizeof(double)))
            return 0;
    }
    return 1;
}

static unsigned char *read_all(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    unsigned char *data = NULL;
    long n;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) > 0 && fseek(f, 0, SEEK_SET) == 0) {
        data = (unsigned char *)malloc((size_t)n);
        if (data && fread(data, 1, (size_t)n, f) != (size_t)n) {
            free(data);
            data = NULL;
        }
        *len = (size_t)n;
    }
    fclose(f);
    return data;
}

static int write_all(const char *path, const unsigned char *data, size_t len) {
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(data, 1, len, f) == len;
    if (f) ok = (fclose(f) == 0) && ok;
    return ok;
}

/* Every byte of small flipped in turn, by one bit and by all eight. */
static void flip_every_byte(const char *small, const char *scratch) {
    char path[4096];
    size_t len = 0, i, n_db, refused = 0, loaded = 0;
    unsigned char *data = read_all(small, &len);
    qtvpr_calibration *cal = qtvpr_calibration_load(small);
    qtvpr_decision want[N_QUERIES], got[N_QUERIES];
    double *s;
    int m;

    CHECK(data != NULL && cal != NULL);
    if (!data || !cal) return;
    n_db = qtvpr_calibration_db_size(cal);
    s = deployment(n_db);
    CHECK(s != NULL && decide(cal, s, n_db, want));
    qtvpr_calibration_free(cal);
    snprintf(path, sizeof path, "%s/flipped.npz", scratch);
    for (i = 0; i < len; i++) {
        for (m = 0; m < 2; m++) {
            unsigned char mask = m == 0 ? (unsigned char)(1u << (i % 8)) : 0xff;
            data[i] ^= mask;
            CHECK(write_all(path, data, len));
            data[i] ^= mask;
            cal = qtvpr_calibration_load(path);
            if (!cal) {
                refused++;
                if (!EXPECT_ERROR(QTVPR_ERR_FILE, "qtvpr_calibration_load: ", path, NULL))
                    fprintf(stderr, "  (byte %zu, mask 0x%02x)\n", i, mask);
                continue;
            }
            loaded++;
            if (qtvpr_calibration_db_size(cal) != n_db || !decide(cal, s, n_db, got) || !same(want, got)) {
                fprintf(stderr, "byte %zu flipped by 0x%02x loads with other decisions\n", i, mask);
                failures++;
            }
            qtvpr_calibration_free(cal);
        }
    }
    printf("hostile: %zu flipped files refused, %zu loaded with identical decisions\n", refused, loaded);
    CHECK(refused > 3 * loaded);
    free(s);
    free(data);
}

/* path is refused with QTVPR_ERR_FILE naming it and member, fast and small. */
static void bomb(const char *path, const char *words) {
    long before = peak_rss_kib();
    double start = now(), seconds;
    qtvpr_calibration *cal = qtvpr_calibration_load(path);
    seconds = now() - start;
    CHECK(cal == NULL);
    EXPECT_ERROR(QTVPR_ERR_FILE, path, words, NULL);
    printf("hostile: %s refused in %.3f s, peak RSS %ld KiB (%+ld KiB): %s\n", path, seconds, peak_rss_kib(),
           peak_rss_kib() - before, qtvpr_last_error());
    CHECK(seconds < 1.0);
    CHECK(peak_rss_kib() - before < 100 * 1024);
    qtvpr_calibration_free(cal); /* NULL, unless a check above failed */
}

/* Every file of the manifest (a path, a tab, a part of its error, a line): refused with
 * QTVPR_ERR_FILE and a message naming the file and holding the part. */
static void hostile_set(const char *manifest) {
    char line[8192];
    int n = 0;
    FILE *f = fopen(manifest, "r");
    CHECK(f != NULL);
    while (f && fgets(line, sizeof line, f)) {
        char *tab = strchr(line, '\t'), *end = strchr(line, '\n');
        qtvpr_calibration *cal;
        if (!tab || !end) {
            CHECK(!"a manifest line is a path, a tab and an error");
            break;
        }
        *tab = *end = '\0';
        cal = qtvpr_calibration_load(line);
        CHECK(cal == NULL);
        if (!EXPECT_ERROR(QTVPR_ERR_FILE, line, tab + 1, NULL)) {
            fprintf(stderr, "  %s: %s\n", line, qtvpr_last_error() ? qtvpr_last_error() : "(no error)");
        }
        qtvpr_calibration_free(cal);
        n++;
    }
    if (f) {
        fclose(f);
    }
    CHECK(n > 40);
}

int main(int argc, char **argv) {
    char fifo[4096];
    double start;
    qtvpr_calibration *cal;

    if (argc < 7 || argc > 8) {
        fprintf(stderr, "usage: %s SCRATCH_DIR SMALL.npz CRC.npz BZIP2_BOMB.npz DEFLATE_BOMB.npz MANIFEST [BIG.npz]\n",
                argv[0]);
        return 2;
    }

    /* A FIFO with no writer: an error at once; a hang is killed by the alarm (exit by
     * SIGALRM, which capi.sh reports as a failure). */
    snprintf(fifo, sizeof fifo, "%s/cal.fifo", argv[1]);
    unlink(fifo);
    CHECK(mkfifo(fifo, 0600) == 0);
    alarm(10);
    start = now();
    cal = qtvpr_calibration_load(fifo);
    alarm(0);
    CHECK(cal == NULL);
    EXPECT_ERROR(QTVPR_ERR_IO, "qtvpr_calibration_load: cannot read", fifo, "is a FIFO with no writer");
    CHECK(now() - start < 1.0);
    qtvpr_calibration_free(cal);
    unlink(fifo);

    /* One flipped bit in s's data: the member's CRC-32. */
    CHECK(qtvpr_calibration_load(argv[3]) == NULL);
    EXPECT_ERROR(QTVPR_ERR_FILE, argv[3], "(array s) is corrupt: its CRC-32 does not match its data", NULL);

    alarm(60);
    flip_every_byte(argv[2], argv[1]);

    bomb(argv[4], "(array s) cannot be decompressed: compression method 12 (bzip2) is not supported");
    bomb(argv[5], "ground truth shape 1x1 does not match calibration similarity shape 5000x1000");
    hostile_set(argv[6]);
    if (argc == 8) {
        cal = qtvpr_calibration_load(argv[7]);
        CHECK(cal == NULL);
        EXPECT_ERROR(QTVPR_ERR_MEMORY, argv[7], "cannot allocate", NULL);
        qtvpr_calibration_free(cal);
    }
    alarm(0);

    if (failures) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("hostile: all checks passed (qtvpr %s)\n", qtvpr_version());
    return 0;
}
