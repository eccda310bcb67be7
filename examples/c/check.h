/* The checks of the C tests (errors.c, hostile.c): a failed check is counted and
 * reported with its file and line, and the test carries on. Not part of the qtvpr API. */
#ifndef QTVPR_EXAMPLE_CHECK_H
#define QTVPR_EXAMPLE_CHECK_H

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "qtvpr.h"

static int failures = 0;

#define CHECK(cond)                                                                                          \
    do {                                                                                                     \
        if (!(cond)) {                                                                                       \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);                         \
            failures++;                                                                                      \
        }                                                                                                    \
    } while (0)

/* The last call failed with code, and its message contains each of the words, a list
 * that ends at the first NULL. Returns whether it did. */
static int expect_error(const char *file, int line, int code, ...) {
    const char *message = qtvpr_last_error();
    const char *word;
    int ok = qtvpr_last_error_code() == code && message != NULL;
    va_list words;
    va_start(words, code);
    while (ok && (word = va_arg(words, const char *)) != NULL)
        ok = strstr(message, word) != NULL;
    va_end(words);
    if (!ok) {
        fprintf(stderr, "%s:%d: expected code %d and its words, got code %d: %s\n", file, line, code,
                qtvpr_last_error_code(), message ? message : "(NULL)");
        failures++;
    }
    return ok;
}
/* EXPECT_ERROR(code, word, ...): words up to a NULL (a trailing NULL is implied). */
#define EXPECT_ERROR(code, ...) expect_error(__FILE__, __LINE__, code, __VA_ARGS__, (const char *)NULL)
#define EXPECT_OK() CHECK(qtvpr_last_error_code() == QTVPR_OK && qtvpr_last_error() == NULL)

#endif /* QTVPR_EXAMPLE_CHECK_H */
