//! Every channel, signal and progress counter between the tasks, in one place.
//!
//! Tasks talk only through what is defined here: no task module imports another task module
//! to reach its queue, so each task can be read (and replaced) on its own. The task graph:
//!
//! ```text
//!   vision ────── LinkEvent::Frame, LinkEvent::Status ──┐
//!                                                       ├─► LINK_EVENTS ──► link ──► UART
//!   param_store ─ LinkEvent::Status ────────────────────┘   (Channel, 4)     │   (to the FC)
//!       ▲                                                                    │
//!       └──────────────── SAVE (Signal<ParamSet>) ───────────────────────────┤
//!   vision ◄───────────── PIPELINE_SETTINGS (Signal<PipelineSettings>) ──────┤
//!   vision ◄───────────── VEHICLE (Mutex<VehicleState>, newest copy) ────────┘
//!
//!   vision ── VIEW_READY (Signal<&mut ViewFrame>) ──► view ──► RTT up channel (to the probe)
//!   vision ◄─ VIEW_FREE (Signal<&mut ViewFrame>) ───── view ◄── RTT down channel
//!   vision ◄─ VIEW_REQUEST (Mutex, newest request) ─── view
//!
//!   vision ── FRAMES_DONE ──┐
//!                           ├──► watchdog ──► IWDG1 (petted while both counters move)
//!   link ──── LINK_LOOPS ───┘
//! ```
//!
//! - [`LINK_EVENTS`]: each frame's estimate and faults for the MAVLink link. A channel, because
//!   every frame's target matters, in order. Four events hold 133 ms of frames at 30 fps
//!   (a [`LinkEvent`] is a few hundred bytes, so about 1 KiB of DTCM); the link takes each one as
//!   soon as it runs (it waits on the channel), so the queue only fills when the link is
//!   stuck, e.g. blocked on a UART that does not drain. (Events posted at boot before the
//!   link runs, the restore report of the parameter store and the camera probe's, wait in
//!   it.) Then [`post_to_link`] drops the event
//!   and counts it ([`dropped_link_events`], in the link's summary) rather than make the
//!   vision task wait: a late frame is worth nothing to the flight controller, a stalled
//!   camera loop costs every frame after it.
//! - [`PIPELINE_SETTINGS`]: the per-frame path's parameters, from the link (which sees
//!   PARAM_SET) to the vision task. A signal: only the newest settings matter, and a burst of
//!   PARAM_SETs within one frame collapses into one update the vision task applies once.
//! - [`VEHICLE`]: the vehicle state (attitude and local position histories) the link decodes
//!   from the autopilot, for the estimator in the vision task, which reads it at each frame's
//!   exposure. A mutex around one copy, not a channel: the estimator wants the whole recent
//!   history at once, not each sample, and the newest copy supersedes the older. The link
//!   writes it after each received chunk that changed it ([`publish_vehicle`]), the vision
//!   task copies it out
//!   before each frame ([`read_vehicle`]); each copy is about 1.3 KiB, a microsecond inside
//!   the critical section, so neither ever holds the lock while it works.
//! - [`SAVE`]: the whole parameter set to write to flash, from the link (after its debounce)
//!   to the parameter store. A signal: each set is complete, so a newer one supersedes an
//!   unsaved older one while a slow erase is in progress.
//! - [`VIEW_READY`] / [`VIEW_FREE`]: the one frame record for a host viewer, handed to the view
//!   task to send and back to the vision task to fill (signals: there is one buffer, so at
//!   most one hand-over is pending each way). [`VIEW_REQUEST`]: the newest request from the
//!   viewer with its time, which the vision task reads before each frame (a mutex around one
//!   copy: only the newest matters, and nobody waits for it).
//! - [`frame_done`] / [`link_alive`]: progress counters the watchdog compares between its
//!   pets (atomics: nobody waits on them, and a counter cannot fill up).
//!
//! Hand-overs between an interrupt handler and its own driver (the DCMI's frame time stamp
//! and fault flags in [`crate::capture`]) stay with that driver: they are not between tasks.

use core::sync::atomic::{AtomicU32, Ordering};

use core::cell::{Cell, RefCell};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;

use embassy_sync::blocking_mutex::Mutex;
use touchdown_core::companion::MavSeverity;
use touchdown_core::filter::{FrameEstimate, VehicleState};
use touchdown_core::frame_stream::ViewRequest;
use touchdown_core::params::{ParamSet, PipelineSettings};

use crate::view::ViewFrame;

/// What the other tasks send the link. (A frame's estimate is a few hundred bytes, a status
/// ~12; boxing the larger variant is not an option without a heap.)
#[allow(clippy::large_enum_variant)]
pub enum LinkEvent {
    /// A processed frame: its exposure time and the estimate at it.
    Frame(FrameEstimate),
    /// A fault or notice for the ground station (STATUSTEXT).
    Status(MavSeverity, &'static str),
}

/// Events queued for the link (see the module docs for the capacity).
pub const LINK_EVENTS_CAPACITY: usize = 4;

/// Events for the link task, received only by it.
pub static LINK_EVENTS: Channel<CriticalSectionRawMutex, LinkEvent, LINK_EVENTS_CAPACITY> =
    Channel::new();

/// Events [`post_to_link`] dropped because [`LINK_EVENTS`] was full.
static DROPPED_LINK_EVENTS: AtomicU32 = AtomicU32::new(0);

/// Hands an event to the link task without waiting; drops (and counts) it when the queue is
/// full.
pub fn post_to_link(event: LinkEvent) {
    if LINK_EVENTS.try_send(event).is_err() {
        DROPPED_LINK_EVENTS.fetch_add(1, Ordering::Relaxed);
    }
}

/// Events dropped since boot because the link's queue was full.
pub fn dropped_link_events() -> u32 {
    DROPPED_LINK_EVENTS.load(Ordering::Relaxed)
}

/// New per-frame path settings from the link task for the vision task (the newest wins).
pub static PIPELINE_SETTINGS: Signal<CriticalSectionRawMutex, PipelineSettings> = Signal::new();

/// The newest copy of the vehicle state, from the link task for the vision task's estimator.
pub static VEHICLE: Mutex<CriticalSectionRawMutex, RefCell<VehicleState>> =
    Mutex::new(RefCell::new(VehicleState::new()));

/// Replaces the shared vehicle state with `vehicle` (called by the link task).
pub fn publish_vehicle(vehicle: &VehicleState) {
    VEHICLE.lock(|shared| shared.borrow_mut().clone_from(vehicle));
}

/// Copies the shared vehicle state into `vehicle` (called by the vision task before a frame).
pub fn read_vehicle(vehicle: &mut VehicleState) {
    VEHICLE.lock(|shared| vehicle.clone_from(&shared.borrow()));
}

/// The parameter set for the parameter store to save (the newest wins if saves pile up).
pub static SAVE: Signal<CriticalSectionRawMutex, ParamSet> = Signal::new();

/// Frames the vision task has finished (it calls [`frame_done`]; the watchdog reads it).
pub static FRAMES_DONE: AtomicU32 = AtomicU32::new(0);
/// Passes of the link task's loop (it calls [`link_alive`]; the watchdog reads it).
pub static LINK_LOOPS: AtomicU32 = AtomicU32::new(0);

/// Reports one finished frame (called by the vision task).
pub fn frame_done() {
    FRAMES_DONE.fetch_add(1, Ordering::Relaxed);
}

/// Reports one pass of the MAVLink loop (called by the link task).
pub fn link_alive() {
    LINK_LOOPS.fetch_add(1, Ordering::Relaxed);
}

/// The frame record, filled by the vision task, for the view task to send.
pub static VIEW_READY: Signal<CriticalSectionRawMutex, &'static mut ViewFrame> = Signal::new();
/// The frame record, sent, back to the vision task.
pub static VIEW_FREE: Signal<CriticalSectionRawMutex, &'static mut ViewFrame> = Signal::new();
/// The newest viewer request and when it came, board µs.
pub static VIEW_REQUEST: Mutex<CriticalSectionRawMutex, Cell<Option<(ViewRequest, u64)>>> =
    Mutex::new(Cell::new(None));

/// Records a viewer request received at `now_us` (called by the view task).
pub fn request_view(request: ViewRequest, now_us: u64) {
    VIEW_REQUEST.lock(|shared| shared.set(Some((request, now_us))));
}

/// The newest viewer request and its time (called by the vision task).
pub fn view_request() -> Option<(ViewRequest, u64)> {
    VIEW_REQUEST.lock(Cell::get)
}
