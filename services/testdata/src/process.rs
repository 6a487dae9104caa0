//! Child processes that do not outlive their test.

use std::process::Child;

/// A child process that is killed and reaped when dropped, so that a test that fails part-way
/// leaves no robot, client or service running after it (and none holding its ports).
pub struct KillOnDrop(Option<Child>);

impl KillOnDrop {
    /// The process, no longer killed on drop (to wait for its output).
    pub fn into_inner(mut self) -> Child {
        self.0.take().expect("a process")
    }
}

impl From<Child> for KillOnDrop {
    fn from(child: Child) -> Self {
        KillOnDrop(Some(child))
    }
}

impl std::ops::Deref for KillOnDrop {
    type Target = Child;
    fn deref(&self) -> &Child {
        self.0.as_ref().expect("a process")
    }
}

impl std::ops::DerefMut for KillOnDrop {
    fn deref_mut(&mut self) -> &mut Child {
        self.0.as_mut().expect("a process")
    }
}

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if let Some(child) = self.0.as_mut() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;
    use std::process::Command;

    #[test]
    fn a_process_is_killed_and_reaped_when_a_test_panics_holding_it() {
        let child = Command::new("sleep")
            .arg("60")
            .spawn()
            .expect("sleep starts");
        let proc_dir = format!("/proc/{}", child.id());
        assert!(Path::new(&proc_dir).exists());
        let unwound = std::panic::catch_unwind(move || {
            let _held = KillOnDrop::from(child);
            panic!("a failed check");
        });
        assert!(unwound.is_err());
        // Killed and reaped: no process, not even a zombie, is left under its id.
        assert!(!Path::new(&proc_dir).exists(), "{proc_dir} is still there");
    }
}
