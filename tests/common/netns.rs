//! Network namespaces for the drills that cut links with iptables (this kernel has no `tc
//! netem`): one joined to the root namespace by a veth pair ([`Netns`]), or several on one
//! LAN ([`Lan`]). Needs root, `ip` (iproute2) and `iptables`; without them a drill fails
//! saying so, never skips. Dropping one removes its namespaces (with their veth pairs), also
//! when the test fails.

use std::process::{Command, Stdio};

pub const REQUIREMENT: &str = "the network drills need root, `ip` (iproute2) and `iptables` \
                               (installed when missing); see tests/README.md";

/// Runs a command; its stdout, or a panic naming it and its stderr.
pub fn run(program: &str, args: &[&str]) -> String {
    let out = Command::new(program)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("`{program} {}`: {e} ({REQUIREMENT})", args.join(" ")));
    assert!(
        out.status.success(),
        "`{program} {}` failed ({}): {}",
        args.join(" "),
        out.status,
        String::from_utf8_lossy(&out.stderr).trim()
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// An X in 1–250 such that no interface has an address in `prefix`.X, tried from `seed` on.
fn free_subnet(prefix: &str, seed: u32) -> u32 {
    let used = run("ip", &["-o", "-4", "addr", "show"]);
    (0..250)
        .map(|i| (seed + i) % 250 + 1)
        .find(|x| !used.contains(&format!(" {prefix}.{x}.")))
        .unwrap_or_else(|| panic!("a free {prefix}.X subnet"))
}

/// Fails loudly unless the drill can run: root, `ip` and `iptables` (their Debian packages
/// installed when missing).
pub fn require_root_and_tools() {
    assert!(
        testdata::debian::is_root(),
        "{REQUIREMENT}: not running as root"
    );
    testdata::debian::require(&[("ip", "iproute2"), ("iptables", "iptables")]);
    for tool in ["ip", "iptables"] {
        let ran = Command::new(tool)
            .arg("-V")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
        assert!(
            ran.is_ok_and(|s| s.success()),
            "{REQUIREMENT}: `{tool} -V` did not run"
        );
    }
}

/// A namespace and its veth pair: `host_ip` on the root side, `ns_ip` inside.
pub struct Netns {
    pub ns: String,
    pub host_if: String,
    pub host_ip: String,
    pub ns_ip: String,
}

impl Netns {
    /// A namespace named for `what` and this process, on a /30 no interface uses.
    pub fn create(what: &str) -> Netns {
        require_root_and_tools();
        let pid = std::process::id();
        let tag: String = what.chars().take(3).collect();
        let x = free_subnet("10.231", pid);
        let net = Netns {
            ns: format!("levelmap-{what}-{pid}"),
            host_if: format!("lm{tag}{pid}h"),
            host_ip: format!("10.231.{x}.1"),
            ns_ip: format!("10.231.{x}.2"),
        };
        // Made before the first command: a setup failing halfway is torn down too.
        let (ns, host_if) = (net.ns.as_str(), net.host_if.as_str());
        let inner_if = format!("lm{tag}{pid}n");
        run("ip", &["netns", "add", ns]);
        run(
            "ip",
            &[
                "link", "add", host_if, "type", "veth", "peer", "name", &inner_if,
            ],
        );
        run("ip", &["link", "set", &inner_if, "netns", ns]);
        let host_cidr = format!("{}/30", net.host_ip);
        run("ip", &["addr", "add", &host_cidr, "dev", host_if]);
        run("ip", &["link", "set", host_if, "up"]);
        let ns_cidr = format!("{}/30", net.ns_ip);
        run("ip", &["-n", ns, "addr", "add", &ns_cidr, "dev", &inner_if]);
        run("ip", &["-n", ns, "link", "set", &inner_if, "up"]);
        run("ip", &["-n", ns, "link", "set", "lo", "up"]);
        net
    }
}

impl Namespace for Netns {
    fn ns(&self) -> &str {
        &self.ns
    }
}

/// A namespace by its name.
impl Namespace for String {
    fn ns(&self) -> &str {
        self
    }
}

/// A network namespace processes run in: the commands that run there.
pub trait Namespace {
    /// The namespace's name (`ip netns`).
    fn ns(&self) -> &str;

    /// `iptables` inside the namespace.
    fn iptables(&self, args: &[&str]) {
        let mut all = vec!["netns", "exec", self.ns(), "iptables"];
        all.extend_from_slice(args);
        run("ip", &all);
    }

    /// `command` to run inside the namespace (`ip netns exec` runs the same program there, in
    /// the same process: its pid is the program's). Its stdio is to be set again.
    fn wrap(&self, command: &Command) -> Command {
        let mut inside = Command::new("ip");
        inside
            .args(["netns", "exec", self.ns()])
            .arg(command.get_program())
            .args(command.get_args());
        inside
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        // Takes the veth pair with it once no process is left inside.
        let _ = Command::new("ip").args(["netns", "del", &self.ns]).output();
        let _ = Command::new("ip")
            .args(["link", "del", &self.host_if])
            .output();
    }
}

/// Machines on one LAN: a namespace per member (`members`, in order: 10.232.X.1, .2, …), each
/// joined by a veth pair to a bridge in a namespace of its own, the switch; the test's own
/// (root) namespace is on it too, at .254, and reaches every member. A member cut by iptables
/// in its namespace loses only the links the rules name. Dropping it removes every namespace
/// (and with them every veth pair), also when the test fails.
pub struct Lan {
    switch: String,
    root_if: String,
    members: Vec<Member>,
}

/// A namespace on a [`Lan`]: its name and address.
pub struct Member {
    pub name: String,
    pub ns: String,
    pub ip: String,
}

impl Namespace for Member {
    fn ns(&self) -> &str {
        &self.ns
    }
}

impl Lan {
    pub fn create(members: &[&str]) -> Lan {
        require_root_and_tools();
        // Tests of one binary run in threads of one process: each LAN has names of its own,
        // and picking a free subnet and taking it is done by one thread at a time.
        static CREATING: std::sync::Mutex<u32> = std::sync::Mutex::new(0);
        let mut made = CREATING.lock().unwrap_or_else(|e| e.into_inner());
        *made += 1;
        let id = format!("{}-{made}", std::process::id());
        let x = free_subnet("10.232", std::process::id() + *made);
        let mut lan = Lan {
            switch: format!("levelmap-lan-{id}"),
            root_if: format!("lmlan{}", id.replace('-', "x")),
            members: Vec::new(),
        };
        // Each made before its first command: a setup failing halfway is torn down too.
        let switch = lan.switch.clone();
        run("ip", &["netns", "add", &switch]);
        run(
            "ip",
            &["-n", &switch, "link", "add", "br0", "type", "bridge"],
        );
        run("ip", &["-n", &switch, "link", "set", "br0", "up"]);
        let join = |port: &str, peer: &str, peer_ns: Option<&str>| {
            let mut add = vec!["-n", &switch, "link", "add", port, "type", "veth", "peer"];
            add.extend(["name", peer]);
            if let Some(ns) = peer_ns {
                add.extend(["netns", ns]);
            }
            run("ip", &add);
            run("ip", &["-n", &switch, "link", "set", port, "master", "br0"]);
            run("ip", &["-n", &switch, "link", "set", port, "up"]);
        };
        for (i, name) in members.iter().enumerate() {
            let member = Member {
                name: name.to_string(),
                ns: format!("levelmap-{name}-{id}"),
                ip: format!("10.232.{x}.{}", i + 1),
            };
            run("ip", &["netns", "add", &member.ns]);
            lan.members.push(member);
            let member = lan.members.last().expect("just pushed");
            join(&format!("to-{name}"), "eth0", Some(&member.ns));
            let cidr = format!("{}/24", member.ip);
            run(
                "ip",
                &["-n", &member.ns, "addr", "add", &cidr, "dev", "eth0"],
            );
            run("ip", &["-n", &member.ns, "link", "set", "eth0", "up"]);
            run("ip", &["-n", &member.ns, "link", "set", "lo", "up"]);
        }
        // The test's end, made in the switch, moved to the test's namespace.
        let root_if = lan.root_if.clone();
        join("to-root", &root_if, None);
        let here = std::process::id().to_string();
        run(
            "ip",
            &["-n", &switch, "link", "set", &root_if, "netns", &here],
        );
        run(
            "ip",
            &[
                "addr",
                "add",
                &format!("10.232.{x}.254/24"),
                "dev",
                &root_if,
            ],
        );
        run("ip", &["link", "set", &root_if, "up"]);
        lan
    }

    /// The member named `name`.
    pub fn member(&self, name: &str) -> &Member {
        self.members
            .iter()
            .find(|m| m.name == name)
            .unwrap_or_else(|| panic!("no {name} on the LAN"))
    }
}

impl Drop for Lan {
    fn drop(&mut self) {
        for ns in self.members.iter().map(|m| &m.ns).chain([&self.switch]) {
            let _ = Command::new("ip").args(["netns", "del", ns]).output();
        }
        let _ = Command::new("ip")
            .args(["link", "del", &self.root_if])
            .output();
    }
}
