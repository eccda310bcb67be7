//! Tells the tests whether the vectorised sort (`platform/sort.rs`) can run on this
//! machine, so that its tests are reported *ignored, this CPU has no AVX-512* where it
//! cannot, instead of passing without running it.
//!
//! The detection is of the machine that builds, which is the machine that runs the
//! tests (`cargo test` does not cross-compile by itself). The library does not use the
//! flag: it chooses its sort at run time (`pulp::x86::V4::try_new`).

fn main() {
    println!("cargo::rustc-check-cfg=cfg(qtvpr_no_avx512)");
    println!("cargo::rerun-if-changed=build.rs");
    if !host_has_avx512() {
        println!("cargo::rustc-cfg=qtvpr_no_avx512");
    }
}

/// The AVX-512 subsets `pulp::x86::V4` requires, on an x86-64 host that builds for
/// x86-64.
fn host_has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if std::env::var("CARGO_CFG_TARGET_ARCH").as_deref() != Ok("x86_64") {
            return false;
        }
        std::is_x86_feature_detected!("avx512f")
            && std::is_x86_feature_detected!("avx512bw")
            && std::is_x86_feature_detected!("avx512cd")
            && std::is_x86_feature_detected!("avx512dq")
            && std::is_x86_feature_detected!("avx512vl")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}
