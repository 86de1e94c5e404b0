//! State shared between the tasks. The controller is used only by thread-mode tasks, so a
//! thread-mode mutex guards it and no interrupt is masked while it runs. The step hand-off
//! is shared with the step generator, which runs on the high-priority interrupt executor,
//! so it uses critical sections (held for a few instructions).

use core::cell::{Cell, RefCell};

use controller::{Controller, ControllerConfig};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::signal::Signal;

static CONTROLLER: Mutex<ThreadModeRawMutex, RefCell<Option<Controller>>> =
    Mutex::new(RefCell::new(None));

/// Creates the controller (once, in `main`).
pub fn init_controller(config: ControllerConfig) {
    CONTROLLER.lock(|c| *c.borrow_mut() = Some(Controller::new(config)));
}

/// Runs `f` on the controller. Panics only if called before [`init_controller`], which
/// `main` runs before spawning any task.
pub fn with_controller<R>(f: impl FnOnce(&mut Controller) -> R) -> R {
    CONTROLLER.lock(|c| {
        let mut guard = c.borrow_mut();
        let controller = guard.as_mut().expect("controller initialised in main");
        f(controller)
    })
}

/// The latest HX711 conversion not yet consumed by the control tick.
pub static LOAD_CONVERSION: Mutex<ThreadModeRawMutex, Cell<Option<i32>>> =
    Mutex::new(Cell::new(None));

/// Signed microsteps handed from the control tick to the step generator, not yet emitted.
pub static PENDING_STEPS: Mutex<CriticalSectionRawMutex, Cell<i32>> = Mutex::new(Cell::new(0));
/// Wakes the step generator when steps are pending.
pub static STEPS_READY: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// Driver enable requested by the controller.
pub static STEPPER_ENABLE: Mutex<CriticalSectionRawMutex, Cell<bool>> =
    Mutex::new(Cell::new(false));
