//! The `twinbench` executable's allocator and lock functions, interposed over the C
//! library's for every library the process loads (an FMU's among them): each counts in
//! [`tb_rtcount`] while a real-time check has the counters armed, then hands the call to
//! the C library (`__libc_malloc` and its kin, which glibc exports for this purpose; the
//! lock functions found once with `dlsym(RTLD_NEXT)`).
//!
//! Only the executable defines them (build.rs exports them to the dynamic symbol table):
//! the library crate, the test binaries and the Python extension keep the C library's.
//! While nothing is armed the cost is one relaxed load per call.

use std::ffi::{c_int, c_void};
use std::sync::atomic::{AtomicUsize, Ordering};
use tb_rtcount::{count, Event};

extern "C" {
    fn __libc_malloc(size: usize) -> *mut c_void;
    fn __libc_calloc(n: usize, size: usize) -> *mut c_void;
    fn __libc_realloc(p: *mut c_void, size: usize) -> *mut c_void;
    fn __libc_free(p: *mut c_void);
    fn __libc_memalign(align: usize, size: usize) -> *mut c_void;
}

/// Tells the counters that allocations can be seen in this process.
pub fn install() {
    find_locks();
    tb_rtcount::set_interposed();
}

#[no_mangle]
pub unsafe extern "C" fn malloc(size: usize) -> *mut c_void {
    count(Event::Malloc);
    __libc_malloc(size)
}

#[no_mangle]
pub unsafe extern "C" fn calloc(n: usize, size: usize) -> *mut c_void {
    count(Event::Calloc);
    __libc_calloc(n, size)
}

#[no_mangle]
pub unsafe extern "C" fn realloc(p: *mut c_void, size: usize) -> *mut c_void {
    count(Event::Realloc);
    __libc_realloc(p, size)
}

#[no_mangle]
pub unsafe extern "C" fn free(p: *mut c_void) {
    if !p.is_null() {
        count(Event::Free);
    }
    __libc_free(p)
}

#[no_mangle]
pub unsafe extern "C" fn memalign(align: usize, size: usize) -> *mut c_void {
    count(Event::AlignedAlloc);
    __libc_memalign(align, size)
}

#[no_mangle]
pub unsafe extern "C" fn aligned_alloc(align: usize, size: usize) -> *mut c_void {
    count(Event::AlignedAlloc);
    __libc_memalign(align, size)
}

#[no_mangle]
pub unsafe extern "C" fn valloc(size: usize) -> *mut c_void {
    count(Event::AlignedAlloc);
    __libc_memalign(page_size(), size)
}

#[no_mangle]
pub unsafe extern "C" fn pvalloc(size: usize) -> *mut c_void {
    count(Event::AlignedAlloc);
    let page = page_size();
    __libc_memalign(page, size.div_ceil(page).max(1) * page)
}

#[no_mangle]
pub unsafe extern "C" fn posix_memalign(out: *mut *mut c_void, align: usize, size: usize) -> c_int {
    count(Event::AlignedAlloc);
    if !align.is_power_of_two() || !align.is_multiple_of(std::mem::size_of::<*mut c_void>()) {
        return libc::EINVAL;
    }
    let p = __libc_memalign(align, size);
    if p.is_null() {
        return libc::ENOMEM;
    }
    *out = p;
    0
}

fn page_size() -> usize {
    // SAFETY: sysconf has no preconditions.
    unsafe { libc::sysconf(libc::_SC_PAGESIZE) as usize }
}

/// The C library's lock functions, in the order of [`LOCKS`]; found by [`install`] (before
/// anything is armed: `dlsym` may allocate).
static NEXT: [AtomicUsize; 5] = [const { AtomicUsize::new(0) }; 5];
const LOCKS: [&std::ffi::CStr; 5] = [
    c"pthread_mutex_lock",
    c"pthread_mutex_trylock",
    c"pthread_rwlock_rdlock",
    c"pthread_rwlock_wrlock",
    c"pthread_spin_lock",
];

fn find_locks() {
    for (slot, name) in NEXT.iter().zip(LOCKS) {
        // SAFETY: dlsym with a valid C string; RTLD_NEXT finds the C library's definition.
        let f = unsafe { libc::dlsym(libc::RTLD_NEXT, name.as_ptr()) } as usize;
        slot.store(f, Ordering::Release);
    }
}

macro_rules! lock_fn {
    ($name:ident, $k:expr) => {
        #[no_mangle]
        pub unsafe extern "C" fn $name(lock: *mut c_void) -> c_int {
            count(Event::Lock);
            let mut f = NEXT[$k].load(Ordering::Acquire);
            if f == 0 {
                // Called before `install` (by a library's constructor): found now.
                find_locks();
                f = NEXT[$k].load(Ordering::Acquire);
            }
            let f: unsafe extern "C" fn(*mut c_void) -> c_int = std::mem::transmute(f);
            f(lock)
        }
    };
}

lock_fn!(pthread_mutex_lock, 0);
lock_fn!(pthread_mutex_trylock, 1);
lock_fn!(pthread_rwlock_rdlock, 2);
lock_fn!(pthread_rwlock_wrlock, 3);
lock_fn!(pthread_spin_lock, 4);
