//! SIGINT and SIGTERM: the first cancels the render (it finishes the current pass and the
//! images are written), a second exits at once with code 130. A signal that the parent set
//! to be ignored (a background job of a non-interactive shell) stays ignored.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::Duration;
use svetlo::integrator::Progress;

/// Signals received so far; the handler only counts (all it may do safely).
static RECEIVED: AtomicU32 = AtomicU32::new(0);

extern "C" fn on_signal(_: libc::c_int) {
    if RECEIVED.fetch_add(1, Ordering::SeqCst) > 0 {
        // SAFETY: _exit is async-signal-safe.
        unsafe { libc::_exit(crate::EXIT_INTERRUPTED as libc::c_int) };
    }
}

/// Install the handlers, unless ignored, and a thread that turns the first signal into
/// `progress.cancel`. Returns the signals left ignored, for a warning.
pub fn install(progress: Arc<Progress>) -> Vec<&'static str> {
    let mut ignored = Vec::new();
    for (sig, name) in [(libc::SIGINT, "SIGINT"), (libc::SIGTERM, "SIGTERM")] {
        // SAFETY: plain sigaction calls with zeroed, then filled, structures.
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(sig, std::ptr::null(), &mut old) != 0 {
                continue;
            }
            if old.sa_sigaction == libc::SIG_IGN {
                ignored.push(name);
                continue;
            }
            let mut new: libc::sigaction = std::mem::zeroed();
            new.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
            new.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut new.sa_mask);
            libc::sigaction(sig, &new, std::ptr::null_mut());
        }
    }
    std::thread::spawn(move || loop {
        if RECEIVED.load(Ordering::SeqCst) > 0 {
            progress.cancel.store(true, Ordering::SeqCst);
            tell!("\ninterrupt: finishing the current pass and writing the image (interrupt again to quit now)");
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    });
    ignored
}
