//! The one generator of the C entry points, for FMI 2.0 ([`export_fmu!`](crate::export_fmu))
//! and FMI 3.0 alike: each symbol is one line, its C signature and the Rust function that
//! answers it, so that a symbol's signature and its handler are read side by side and the
//! two versions' lists differ only where the standards do.

/// `name(arg: Type, …) -> Status => handler(arg, …);`, one per symbol: a `#[no_mangle]`
/// `extern "C"` function that calls the handler. Every handler catches panics and returns
/// the status the standard wants (the runtime's job); the entry point only forwards.
#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_entry_points {
    ($( $name:ident ( $($arg:ident : $t:ty),* $(,)? ) $(-> $ret:ty)? => $body:expr; )*) => {
        $(
            #[no_mangle]
            pub unsafe extern "C" fn $name($($arg: $t),*) $(-> $ret)? {
                $body
            }
        )*
    };
}
