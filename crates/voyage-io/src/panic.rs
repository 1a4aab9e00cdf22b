//! Third-party decoders may panic on malformed files. Where they are called the panic is
//! caught and becomes an error naming the file; this keeps the panic's report off the screen.

thread_local! {
    /// Set while a panic would be caught and turned into an `voyage_core::Error`.
    static CAUGHT: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` (which catches panics itself) with panic reports silenced on this thread: the
/// panic becomes an ordinary error naming the file, and the user should see that one line,
/// not a backtrace. Takes effect with [`install_panic_hook`].
pub(crate) fn quietly<T>(f: impl FnOnce() -> T) -> T {
    let before = CAUGHT.with(|c| c.replace(true));
    let out = f();
    CAUGHT.with(|c| c.set(before));
    out
}

/// Installs a panic hook that stays silent for panics the library catches (in third-party
/// decoders fed malformed files) and reports all others as before. For programs to call once.
pub fn install_panic_hook() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !CAUGHT.with(|c| c.get()) {
            previous(info);
        }
    }));
}
