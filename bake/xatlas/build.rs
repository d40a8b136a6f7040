//! Compiles the vendored xatlas (vendor/xatlas.cpp, MIT, see vendor/LICENSE)
//! with its C interface, single-threaded so that an atlas depends on its
//! inputs alone, and optimized even in debug builds (a debug xatlas is
//! tens of times slower).

fn main() {
    println!("cargo:rerun-if-changed=vendor/xatlas.cpp");
    println!("cargo:rerun-if-changed=vendor/xatlas.h");
    println!("cargo:rerun-if-changed=vendor/xatlas_c.h");
    cc::Build::new()
        .cpp(true)
        .file("vendor/xatlas.cpp")
        .flag_if_supported("-std=c++11")
        .define("XATLAS_C_API", "1")
        .define("XA_MULTITHREADED", "0")
        .define("NDEBUG", None)
        .opt_level(2)
        .debug(false)
        .warnings(false)
        .compile("xatlas");
}
