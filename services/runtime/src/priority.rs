//! Background threads that yield to a service's own work: a thread lowers its CPU priority
//! (its nice value; Linux schedules each thread on its own) so that, on busy cores, it takes
//! the time the service's foreground threads leave.

/// Lowers the calling thread's priority to `nice` (0 normal, 19 the lowest); on an error
/// the thread keeps its priority. Only the calling thread changes: call it first in a thread
/// of its own, never on a pool's thread. Elsewhere than on Linux it does nothing.
pub fn lower_this_thread(nice: i32) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        let id = rustix::thread::gettid();
        rustix::process::setpriority_process(Some(id), nice)?;
    }
    #[cfg(not(target_os = "linux"))]
    let _ = nice;
    Ok(())
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    #[test]
    fn only_the_calling_thread_is_lowered() {
        let before = rustix::process::getpriority_process(None).expect("own priority");
        let lowered = std::thread::spawn(|| {
            super::lower_this_thread(19).expect("lowered");
            rustix::process::getpriority_process(None).expect("its priority")
        })
        .join()
        .expect("the thread ends");
        assert_eq!(lowered, 19);
        let after = rustix::process::getpriority_process(None).expect("own priority");
        assert_eq!(after, before, "the caller's thread keeps its priority");
    }
}
