//! Ctrl-C in a pipeline call that runs without the GIL.
//!
//! Python runs its signal handlers only on its main thread and only while that holds the GIL,
//! so a call that releases it for minutes would otherwise ignore Ctrl-C until it returns. The
//! pipeline runs on a worker thread instead while the calling thread waits, running the
//! handlers; when one raises (`KeyboardInterrupt`, or what the program's own handler raises),
//! the worker unwinds out of the pipeline at its next progress report (every frame of a
//! trajectory, every epoch, every element the cubature fit adds, every stage's end) and the
//! call raises that exception. A stage's artifact is written whole or not at all (a temporary file renamed into
//! place), so an interrupted stage leaves the cache as it was and the next call computes it.

use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use pyo3::prelude::*;

/// How often the waiting thread runs Python's signal handlers: Ctrl-C is answered within this
/// and the worker's next progress report.
const CHECK_EVERY: Duration = Duration::from_millis(50);

/// The worker's stack, as large as a main thread's (spawned threads get 2 MiB by default).
const WORKER_STACK: usize = 8 << 20;

/// The payload the unwinding carries out of the pipeline (not a panic: no hook prints it).
struct Interrupted;

/// Whether a call was stopped, and the exception that stopped it.
pub(crate) struct Interrupt {
    raised: Mutex<Option<PyErr>>,
    stopped: AtomicBool,
}

impl Interrupt {
    pub(crate) fn new() -> Self {
        Self {
            raised: Mutex::new(None),
            stopped: AtomicBool::new(false),
        }
    }

    /// Unwinds out of the work [`Interrupt::run`] runs when the call was stopped; from the
    /// pipeline's progress reports, on any thread.
    pub(crate) fn check(&self) {
        if self.stopped.load(Ordering::SeqCst) {
            resume_unwind(Box::new(Interrupted));
        }
    }

    /// Keeps `e` as the call's exception (the first one kept) and stops the call.
    fn keep(&self, e: PyErr) {
        self.raised
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get_or_insert(e);
        self.stopped.store(true, Ordering::SeqCst);
    }

    /// Stops the call with `e` from inside the work (a callback that raised it).
    pub(crate) fn stop(&self, e: PyErr) -> ! {
        self.keep(e);
        resume_unwind(Box::new(Interrupted))
    }

    /// Runs `work` on a worker thread without the GIL while this thread runs Python's signal
    /// handlers every [`CHECK_EVERY`]: when one raises (Ctrl-C's `KeyboardInterrupt`), the
    /// work unwinds at its next [`Interrupt::check`] and that exception is returned in place of
    /// its value. A panic of the work goes on as a panic here.
    pub(crate) fn run<T: Send>(
        &self,
        py: Python<'_>,
        work: impl FnOnce() -> T + Send,
    ) -> PyResult<T> {
        let main = std::thread::current();
        let outcome = std::thread::scope(|s| {
            let worker = std::thread::Builder::new()
                .name("latent-dynamics pipeline".into())
                .stack_size(WORKER_STACK)
                .spawn_scoped(s, move || {
                    let outcome = catch_unwind(AssertUnwindSafe(work));
                    main.unpark();
                    outcome
                })
                .map_err(|e| {
                    pyo3::exceptions::PyRuntimeError::new_err(format!(
                        "cannot start the pipeline's thread: {e}"
                    ))
                })?;
            while !worker.is_finished() {
                if let Err(e) = py.check_signals() {
                    self.keep(e);
                }
                py.detach(|| std::thread::park_timeout(CHECK_EVERY));
            }
            PyResult::Ok(worker.join())
        })?;
        // A signal handled after the work's last check is raised all the same, as Python
        // raises one caught during any call when it returns (the handler used the signal up).
        let raised = self.raised.lock().unwrap_or_else(|e| e.into_inner()).take();
        match outcome {
            Ok(Err(payload)) | Err(payload) if !payload.is::<Interrupted>() => {
                resume_unwind(payload)
            }
            Ok(Ok(value)) if raised.is_none() => Ok(value),
            _ => Err(raised.unwrap_or_else(|| {
                pyo3::exceptions::PyKeyboardInterrupt::new_err("the pipeline was interrupted")
            })),
        }
    }
}
