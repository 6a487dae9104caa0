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
