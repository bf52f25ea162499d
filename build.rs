//! The `twinbench` executable's link: the allocator and lock functions it interposes
//! (src/interpose.rs) go into its dynamic symbol table, so that the libraries it loads call
//! them. The model registry's build (the FMU libraries, the generated list) is the library's:
//! crates/bench/build.rs.

/// The functions src/interpose.rs defines.
const INTERPOSED: [&str; 14] = [
    "malloc",
    "calloc",
    "realloc",
    "free",
    "memalign",
    "aligned_alloc",
    "valloc",
    "pvalloc",
    "posix_memalign",
    "pthread_mutex_lock",
    "pthread_mutex_trylock",
    "pthread_rwlock_rdlock",
    "pthread_rwlock_wrlock",
    "pthread_spin_lock",
];

fn main() {
    for name in INTERPOSED {
        println!("cargo:rustc-link-arg-bin=twinbench=-Wl,--export-dynamic-symbol={name}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
