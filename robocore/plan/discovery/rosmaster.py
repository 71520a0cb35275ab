"""The ROS master: ROS 1's discovery (robot.yaml ``discovery.kind: rosmaster``, ROS 1's default).

One ``roscore`` (the master plus ``rosout``) runs on the first host, or on the host of robot.yaml's
one ``discovery.servers`` entry, started before the nodes. Every node gets ``ROS_MASTER_URI`` and
an address that the other nodes can connect back to: ROS 1 nodes publish to each other directly
over TCPROS, on ports they choose at random, so each node advertises its host's address
(``ROS_IP``, or ``ROS_HOSTNAME`` for a DNS name). A container on a bridge network advertises its
own address instead, which only its own host can reach (validate refuses such a component on a
robot of several hosts). ROS 1 has no shared-memory transport: the robot's ``transport`` only
decides the containers' IPC namespace, as for any kind.
"""

from __future__ import annotations

import ipaddress

from robocore.plan.addresses import bare, bracketed
from robocore.plan.discovery.base import (
    IN_CONTAINERS,
    READY,
    STOPPED,
    WAITING,
    Discovery,
    FileLocator,
    Readiness,
    ServerEndpoint,
    ServerProcess,
    ServerState,
    last_error_line,
    plain_text,
)
from robocore.plan.naming import ENTRYPOINT

#: What roscore logs once the master serves and rosout runs.
MASTER_READY = "started core service [/rosout]"
#: What roscore logs when it cannot serve (a port taken, another master on it).
MASTER_FAILED = ("Unable to start XML-RPC server", "another roscore/master is already running", "RLException")
PORT_HINT = ("is another ROS master (or another program) using that port on the host? "
             "choose another port in robot.yaml (discovery.servers[0].port)")
#: roscore, rospy and the ROS 1 tools are Python, and roscpp's console is block-buffered off a terminal:
#: without these their output reaches the container's log only when a buffer fills (the master's readiness
#: is read from it).
UNBUFFERED = {"PYTHONUNBUFFERED": "1", "ROSCONSOLE_STDOUT_LINE_BUFFERED": "1"}
#: Set in a bridge container's environment: the entrypoint then advertises the container's own address.
ROS_IP_FROM_CONTAINER = "ROBOCORE_ROS_IP_FROM_CONTAINER"


def advertised_address(address: str) -> dict[str, str]:
    """How a node on a host at ``address`` tells others where to reach it: ``ROS_IP`` for an IP address,
    ``ROS_HOSTNAME`` for a name (ROS 1 takes one or the other)."""
    plain = bare(address)
    try:
        ip = ipaddress.ip_address(plain)
    except ValueError:
        return {"ROS_HOSTNAME": plain}
    return {"ROS_IP": str(ip), **({"ROS_IPV6": "on"} if ip.version == 6 else {})}


class RosMaster(Discovery):
    """One ROS master (``roscore``) per robot; every node and tool a client of it."""

    kind = "rosmaster"
    nodes_register_once = True
    server_down = ("the ROS master is down: connected nodes keep exchanging messages, but nothing new can connect "
                   "(a restarted node, a new subscriber, rostopic) until `robocore run` starts it again")

    def servers(self) -> list[ServerEndpoint]:
        """The master (robot.yaml allows one)."""
        server = self.robot.discovery_servers[0]
        host = self.robot.host(server.host)
        return [ServerEndpoint(index=0, host=host.name, address=host.ip, port=self.robot.server_port(server))]

    @property
    def master_uri(self) -> str:
        """``http://<master host>:<port>``, the ``ROS_MASTER_URI`` of every node."""
        master = self.servers()[0]
        return f"http://{bracketed(master.address)}:{master.port}"

    def server_process(self, index: int) -> ServerProcess:
        """``roscore`` on the master's port, advertising its host's address (rosout is a node too)."""
        master = self.servers()[index]
        env = {"ROS_MASTER_URI": self.master_uri, **UNBUFFERED, **advertised_address(master.address)}
        return ServerProcess(command=("roscore", "-p", str(master.port)), environment=env)

    def client_environment(self, host: str, files: FileLocator = IN_CONTAINERS, *,
                           network_mode: str = "host") -> dict[str, str]:
        """The master's URI and the address of ``host`` (a bridge container: its own, set at start)."""
        if network_mode == "bridge":
            return {"ROS_MASTER_URI": self.master_uri, **UNBUFFERED, ROS_IP_FROM_CONTAINER: "1"}
        return {"ROS_MASTER_URI": self.master_uri, **UNBUFFERED, **advertised_address(self.robot.host(host).ip)}

    def observer_environment(self, host: str | None = None, files: FileLocator = IN_CONTAINERS) -> dict[str, str]:
        """The master's URI, and the host's address on the robot (off the robot a tool only asks the master)."""
        if host is None:
            return {"ROS_MASTER_URI": self.master_uri}
        return self.client_environment(host, files)

    def files(self) -> dict[str, str]:
        """None: everything a node needs is in its environment."""
        return {}

    def readiness(self, log_text: str, state: ServerState) -> Readiness:
        """Ready once rosout runs; failed when roscore says it cannot serve, stopped, restarted or timed out."""
        text = plain_text(log_text)
        said = [line.strip() for line in text.splitlines() if any(marker in line for marker in MASTER_FAILED)]
        if said:
            return Readiness("failed", said[-1][-200:], hint=PORT_HINT)
        if state.restart_count == 0 and MASTER_READY in text:
            return READY
        if state.restart_count > 0 or state.status in STOPPED or state.timed_out:
            return Readiness("failed", last_error_line(text)[-200:], hint=PORT_HINT)
        return WAITING

    def node_list_argv(self, spin_seconds: float) -> list[str]:
        """``rosnode list``: the master knows every registered node at once (no spin needed)."""
        return [ENTRYPOINT, "rosnode", "list"]
