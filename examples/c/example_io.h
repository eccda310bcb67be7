/*
 * What the examples need besides qtvpr: a minimal reader of 2-D little-endian
 * float32/float64 .npy files (NumPy's format, versions 1 to 3), so that they read the
 * same similarity matrices as `qtvpr-cli`, and a decision printed as a line of
 * `qtvpr-cli stream --format jsonl`. Not part of the qtvpr API: a robot has its scores
 * in memory already.
 *
 * Header-only: static functions, for C and C++ alike.
 */
#ifndef QTVPR_EXAMPLE_IO_H
#define QTVPR_EXAMPLE_IO_H

#include <float.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "qtvpr.h"

typedef struct {
    size_t rows, cols;
    size_t itemsize;   /* 4: float, 8: double */
    int fortran_order; /* 0: row-major (C order), 1: column-major */
    void *data;        /* rows * cols items; free() it */
} npy_matrix;

/* The value of key in a .npy header dictionary (past the key and its spaces), or NULL. */
static const char *npy_value(const char *header, const char *key) {
    const char *p = strstr(header, key);
    return p ? p + strlen(key) + strspn(p + strlen(key), " ") : NULL;
}

/* Read path into *m. Returns 0, or -1 after printing what is wrong to stderr. */
static int npy_read(const char *path, npy_matrix *m) {
    unsigned char pre[12];
    char *header = NULL;
    size_t header_len, n;
    int ok = 0;
    FILE *f = fopen(path, "rb");
    memset(m, 0, sizeof *m);
    if (!f) {
        perror(path);
        return -1;
    }
    if (fread(pre, 1, 10, f) != 10 || memcmp(pre, "\x93NUMPY", 6) != 0 || pre[6] < 1 || pre[6] > 3) {
        fprintf(stderr, "%s: not a .npy file\n", path);
        goto done;
    }
    if (pre[6] == 1) {
        header_len = (size_t)pre[8] | (size_t)pre[9] << 8;
    } else {
        if (fread(pre + 10, 1, 2, f) != 2) goto bad_header;
        header_len = (size_t)pre[8] | (size_t)pre[9] << 8 | (size_t)pre[10] << 16 | (size_t)pre[11] << 24;
    }
    header = (char *)malloc(header_len + 1);
    if (!header || fread(header, 1, header_len, f) != header_len) goto bad_header;
    header[header_len] = '\0';
    {
        const char *descr = npy_value(header, "'descr':");
        const char *order = npy_value(header, "'fortran_order':");
        const char *shape = npy_value(header, "'shape':");
        if (!descr || !order || !shape) goto bad_header;
        if (strncmp(descr, "'<f4'", 5) == 0) {
            m->itemsize = 4;
        } else if (strncmp(descr, "'<f8'", 5) == 0) {
            m->itemsize = 8;
        } else {
            fprintf(stderr, "%s: dtype is not <f4 or <f8\n", path);
            goto done;
        }
        m->fortran_order = strncmp(order, "True", 4) == 0;
        if (sscanf(shape, "(%zu, %zu)", &m->rows, &m->cols) != 2) {
            fprintf(stderr, "%s: not a 2-D array\n", path);
            goto done;
        }
    }
    if (m->cols && m->rows > SIZE_MAX / m->itemsize / m->cols) goto bad_header;
    n = m->rows * m->cols;
    m->data = malloc(n * m->itemsize + 1);
    if (!m->data || fread(m->data, m->itemsize, n, f) != n) {
        fprintf(stderr, "%s: truncated data\n", path);
        goto done;
    }
    ok = 1;
    goto done;
bad_header:
    fprintf(stderr, "%s: malformed .npy header\n", path);
done:
    free(header);
    fclose(f);
    if (!ok) {
        free(m->data);
        m->data = NULL;
    }
    return ok ? 0 : -1;
}

/* Copy column j of m (a |DB| x |Q| similarity matrix: one query's scores) into out,
 * which holds m->rows items of m's type. */
static void npy_column(const npy_matrix *m, size_t j, void *out) {
    const char *data = (const char *)m->data;
    size_t i;
    if (m->fortran_order) {
        memcpy(out, data + j * m->rows * m->itemsize, m->rows * m->itemsize);
        return;
    }
    for (i = 0; i < m->rows; i++)
        memcpy((char *)out + i * m->itemsize, data + (i * m->cols + j) * m->itemsize, m->itemsize);
}

/* A double as the CLI's JSON has it, null for NaN (no confidence) or infinite. */
static void print_number(double x) {
    if (x != x || x > DBL_MAX || x < -DBL_MAX)
        printf("null");
    else
        printf("%.17g", x);
}

/* Print d as `qtvpr-cli stream --format jsonl` does: the eleven fields of the decision
 * record, the same keys in the same order in both matching modes (confidence and
 * confidence_lower95 null in multi matching, where they are NaN), then the margin
 * gate's margin and gate when it is on, then the sequence gate's consistency and
 * consistency_level when it is on (each NaN when its gate is off); %.17g gives every
 * double exactly (the CLI writes the shortest form of the same value, and null for an
 * infinite one: a reject-all gate). */
static void print_decision(const qtvpr_decision *d) {
    printf("{\"query\":%zu,\"query_quantile\":%.17g,\"weight\":%.17g,\"quantile\":%.17g,"
           "\"threshold\":%.17g,\"best\":%zu,\"score\":%.17g,\"accepted\":%zu,\"accept\":%s",
           d->query, d->query_quantile, d->weight, d->quantile, d->threshold, d->best, d->score, d->accepted,
           d->accept ? "true" : "false");
    printf(",\"confidence\":");
    print_number(d->confidence);
    printf(",\"confidence_lower95\":");
    print_number(d->confidence_lower95);
    if (d->margin == d->margin) {
        printf(",\"margin\":%.17g,\"gate\":", d->margin);
        if (d->gate > DBL_MAX)
            printf("null");
        else
            printf("%.17g", d->gate);
    }
    if (d->consistency_level == d->consistency_level)
        printf(",\"consistency\":%.17g,\"consistency_level\":%.17g", d->consistency, d->consistency_level);
    printf("}\n");
}

#endif /* QTVPR_EXAMPLE_IO_H */
