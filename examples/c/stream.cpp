// Online thresholds from C++17: stream.c with the handles in RAII wrappers, so that
// every path (an exception included) frees them, and errors as exceptions.
//
//     stream_cpp CAL.npz DEPLOY.npy [K PRECISION WINDOW MIN_WINDOW [GATE]]
//
// Build: c++ -std=c++17 -Iinclude examples/c/stream.cpp -Ltarget/release -lqtvpr -o stream_cpp
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "example_io.h"
#include "qtvpr.h"

namespace qtvpr {

struct CalibrationFree {
    void operator()(qtvpr_calibration *cal) const { qtvpr_calibration_free(cal); }
};
struct OnlineFree {
    void operator()(qtvpr_online *o) const { qtvpr_online_free(o); }
};
using Calibration = std::unique_ptr<qtvpr_calibration, CalibrationFree>;
using Online = std::unique_ptr<qtvpr_online, OnlineFree>;

// This thread's last qtvpr error as an exception.
[[noreturn]] void fail() {
    const char *message = qtvpr_last_error();
    throw std::runtime_error(message ? message : "unknown qtvpr error");
}

Calibration load(const std::string &path) {
    Calibration cal(qtvpr_calibration_load(path.c_str()));
    if (!cal) fail();
    return cal;
}

// Every parameter of opts "the calibration file's" (qtvpr_online_options_init) but
// those the caller sets.
Online online(const Calibration &cal, const qtvpr_online_options &opts) {
    Online o(qtvpr_online_new_with(cal.get(), &opts));
    if (!o) fail();
    return o;
}

template <typename T> qtvpr_decision push(const Online &o, const std::vector<T> &scores) {
    qtvpr_decision d;
    int rc;
    if constexpr (sizeof(T) == 4)
        rc = qtvpr_online_push_f32(o.get(), scores.data(), scores.size(), &d);
    else
        rc = qtvpr_online_push_f64(o.get(), scores.data(), scores.size(), &d);
    if (rc != QTVPR_OK) fail();
    return d;
}

} // namespace qtvpr

struct NpyFree {
    void operator()(npy_matrix *m) const { std::free(m->data); }
};

template <typename T> void stream(const qtvpr::Online &o, const npy_matrix &s) {
    std::vector<T> column(s.rows);
    for (size_t j = 0; j < s.cols; j++) {
        npy_column(&s, j, column.data());
        qtvpr_decision d = qtvpr::push(o, column);
        print_decision(&d);
    }
}

int main(int argc, char **argv) {
    if (argc != 3 && argc != 7 && argc != 8) {
        std::fprintf(stderr, "usage: %s CAL.npz DEPLOY.npy [K PRECISION WINDOW MIN_WINDOW [GATE]]\n", argv[0]);
        return 2;
    }
    try {
        qtvpr::Calibration cal = qtvpr::load(argv[1]);
        qtvpr_online_options opts;
        qtvpr_online_options_init(&opts);
        if (argc >= 7) {
            opts.k = std::stoul(argv[3]);
            opts.precision = std::stod(argv[4]);
            opts.window = std::stoul(argv[5]);
            opts.min_window = std::stoul(argv[6]);
        }
        if (argc == 8) opts.gate = argv[7];
        qtvpr::Online o = qtvpr::online(cal, opts);
        cal.reset(); // the online state keeps what it needs of the calibration
        npy_matrix s;
        if (npy_read(argv[2], &s) != 0) return 1;
        std::unique_ptr<npy_matrix, NpyFree> data(&s);
        if (s.itemsize == 4)
            stream<float>(o, s);
        else
            stream<double>(o, s);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "error: %s\n", e.what());
        return 1;
    }
    return 0;
}
