/* SPDX-License-Identifier: MIT */
/*
 * SocketCanBus: the CanBus of a Linux SocketCAN interface (can0, vcan0): one
 * raw CAN socket (PF_CAN, CAN_RAW), non-blocking, bound to the interface.
 *
 * open() sets the socket up:
 *  - kernel filters from the CanFilter list (CAN_RAW_FILTER); an empty list
 *    receives no ordinary frames at all. A filter matches only frames of its
 *    own kind (11-bit or 29-bit) and never remote (RTR) frames.
 *  - error frames (CAN_RAW_ERR_FILTER: TX timeout, controller, bus-off,
 *    restarted, protocol, no ACK, bus error) always, whatever the filters;
 *    they only feed CanStats and the state, receive() never returns them.
 *  - its own frames are not received back (CAN_RAW_RECV_OWN_MSGS off); other
 *    sockets on the same host (candump, a second SocketCanBus) do see them.
 *  - CAN FD frames (CAN_RAW_FD_FRAMES) when CanOptions::fd; the interface must
 *    then have the CAN FD MTU (72), else open() fails saying so.
 *  - reception timestamps from the kernel (SO_TIMESTAMPNS, CLOCK_REALTIME)
 *    moved onto CLOCK_MONOTONIC with the offset between the two clocks taken
 *    when the frame is read; the read time when the kernel gave none.
 *  - the kernel's count of frames this socket lost (SO_RXQ_OVFL).
 * An interface that does not exist yet, or exists but is down, is not an
 * error: at boot the sensor's CAN interface may appear (a USB adapter, an SPI
 * controller's driver) or be configured (systemd-networkd sets the bitrate and
 * brings it up) after dockposed started, and the camera and LEDs should not
 * wait for it. open() then succeeds with the bus in state Down, fd() -1,
 * lastError() saying what is missing and that it is waited for:
 *    can: no CAN interface "can0" (CAN interfaces present: vcan0); waiting for it (retried every 500 ms)
 *    can: interface "can0" is down (ip link set can0 up type can bitrate 500000); waiting for it (retried every 500 ms)
 * and poll() reopens it as after a link loss (below; that first join does not
 * count in restarts). Every other problem is
 * one the interface appearing would not fix, and open() fails naming it:
 *    can: "can0:1" is not a valid interface name (1 to 15 characters, no '/', ':' or spaces)
 *    can: this kernel has no SocketCAN support (socket(PF_CAN): Address family not supported by protocol)
 *    can: interface "eth0" is not a CAN interface
 *    can: interface "can0" does not support CAN FD (MTU 16, not 72: ip link set can0 type can ... fd on)
 * After a failed open() the bus is Closed: send() refuses (tx_errors, false),
 * poll() and receive() do nothing; nothing is retried until open() is called again.
 *
 * What each situation does (the vcan tests in the VM rely on this):
 *  - send() (CanBusBase's): the frame joins the transmit queue (tx_queue_depth
 *    frames, oldest dropped and counted in tx_dropped when full, send() then
 *    returns false), then as many queued frames as the kernel takes are
 *    written, oldest first (tx_frames). Refused without queueing (tx_errors,
 *    false): an id wider than 11 bits (29 when extended), an FD frame on a bus
 *    opened without fd. A classic frame's len is clamped to 8; an FD frame's
 *    to 64 and rounded up to the next CAN FD length (12, 16, 20, 24, 32, 48),
 *    padded with zeros, as the bus would carry it. FD frames go without bit
 *    rate switching (CANFD_BRS clear).
 *  - ENOBUFS (the interface's queue, txqueuelen, is full) or EAGAIN (the
 *    socket's send buffer is full): writing stops, the frame stays queued,
 *    tx_enobufs counts one per refused write; the next send() or poll() tries
 *    again. Note vcan has no queue of its own (tx_queue_len 0, it delivers at
 *    once), so shrinking its txqueuelen alone gives no ENOBUFS; a slow qdisc
 *    whose queue is txqueuelen long does (tests/vm/test_vm_socketcan.cpp:
 *    ip link set vcan0 txqueuelen 4; tc qdisc add dev vcan0 root handle 1:
 *    tbf rate 1kbit burst 32 latency 10s; tc qdisc add dev vcan0 parent 1:1
 *    pfifo, with CONFIG_NET_SCH_TBF).
 *  - EINVAL / EMSGSIZE / EOVERFLOW on a write (the kernel refuses that frame):
 *    the frame is dropped, tx_errors counts it, the next one goes.
 *  - any other write error (ENETDOWN: interface set down; ENXIO / ENODEV: it
 *    vanished; tx_errors counts it, the frame stays queued), or any read
 *    error but EAGAIN / EINTR (ENETDOWN, ENODEV): the socket is closed,
 *    state Down, fd() -1; frames keep queueing (oldest dropped). poll() tries
 *    to reopen at its next call, then every kReopenInterval_ms (500 ms) until
 *    the interface exists and is up again; then state ErrorActive, restarts
 *    + 1, the queue flushes. The kernel filters and options of open() are
 *    used again. lastError() says why the bus went down, then why the latest
 *    reopening failed.
 *  - poll(): flushes the queue, then reads what the kernel has (at most
 *    kMaxReadsPerPoll frames per call; the rest waits in the socket) into a
 *    ring of kRxRingFrames frames; a full ring drops its oldest frame
 *    (counted, with the kernel's own drops, in rxDropped()). Error frames
 *    update CanStats (classifyErrorFrame): bus-off -> BusOff (the queue waits:
 *    writes get ENOBUFS until the controller restarts, which takes the
 *    interface's restart-ms: ip link set can0 type can restart-ms 100),
 *    restarted -> ErrorActive, controller warning / passive / back to active.
 *  - receive(): the oldest frame of the ring (poll() first when it is empty).
 *
 * Threads: the frame thread owns the bus; stats() and rxDropped() are safe
 * from any thread (CanBusBase: a copy under a mutex, refreshed at the end of
 * every call).
 *
 * Allocates: the constructor and open() (the kernel filters, error text);
 * send(), poll() (reopening included), receive(), stats() and rxDropped()
 * never. name() and lastError() return a new string.
 */
#pragma once

#include <linux/can.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "hal/can_bus_base.h"
#include "hal/status.h"

namespace dockpose::hal {

/* What SocketCanBus asks of the kernel: open() with these settings. */
struct SocketCanOpenRequest {
	const char *interface = "";
	std::span<const can_filter> filters; /* kernel filters (socketcan::toKernelFilter) */
	bool fd = false; /* CAN_RAW_FD_FRAMES */
	int bitrate = 0; /* bit/s, only for the hint when it is down */
};

/* One frame read from the socket. */
struct SocketCanRead {
	canfd_frame frame{}; /* size CAN_MTU: its start is a can_frame */
	std::size_t size = 0; /* bytes read: CAN_MTU or CANFD_MTU */
	std::int64_t timestamp_ns = 0; /* reception, CLOCK_MONOTONIC */
	bool has_drop_count = false;
	std::uint32_t drop_count = 0; /* frames the socket lost, a running count */
};

/* What SocketCanIo::open() found. */
enum class SocketCanOpenResult : std::uint8_t {
	Opened,
	NotReady, /* the interface does not exist or is down: it may come later */
	Failed, /* anything else (no SocketCAN, not a CAN interface, no CAN FD, a socket error) */
};

/*
 * The kernel side of a SocketCanBus: a raw CAN socket. The bus talks to it
 * only through this, so the bus's queueing, error and reopening logic can be
 * tested without a CAN-capable kernel. makeKernelSocketCanIo() is the real one.
 * Every call never blocks; errors are returned as errno values.
 */
class SocketCanIo
{
public:
	virtual ~SocketCanIo() = default;
	SocketCanIo() = default;
	SocketCanIo(const SocketCanIo &) = delete;
	SocketCanIo &operator=(const SocketCanIo &) = delete;

	/*
	 * Open, configure and bind a socket (closing any open one). When it is
	 * not Opened, the message (NUL-terminated, truncated to fit) is in
	 * error. With describe, a missing interface's message lists the
	 * interfaces present (allocates); without it, never allocates.
	 */
	virtual SocketCanOpenResult open(const SocketCanOpenRequest &request, bool describe,
					 std::span<char> error) = 0;
	virtual void close() = 0;
	/* Write one CAN_MTU or CANFD_MTU sized frame: 0, or the errno. */
	virtual int write(const void *frame, std::size_t size) = 0;
	/* Read one frame: 0, or the errno (EAGAIN: nothing waiting). */
	virtual int read(SocketCanRead *out) = 0;
	/* CLOCK_MONOTONIC, ns (hal/clock.h). */
	virtual std::int64_t nowNs() const = 0;
	/* The socket, for poll(2) or select(2); -1 when closed. */
	virtual int fd() const = 0;
};

std::unique_ptr<SocketCanIo> makeKernelSocketCanIo();

class SocketCanBus : public CanBusBase
{
public:
	static constexpr int kReopenInterval_ms = 500;
	static constexpr int kRxRingFrames = 64;
	static constexpr int kMaxReadsPerPoll = 256;

	/* interface: "can0". bitrate (bit/s) only goes into the hint when it is down. Allocates. */
	explicit SocketCanBus(std::string interface, int bitrate = 500000);
	/* The same over another kernel side (tests). Allocates. */
	SocketCanBus(std::string interface, std::unique_ptr<SocketCanIo> io, int bitrate = 500000);
	~SocketCanBus() override;

	/* name(): "socketcan:can0" */
	Status open(std::span<const CanFilter> filters, const CanOptions &options) override;
	void close() override;
	void poll() override;

	/* The socket (for poll(2) on readability); -1 when closed or Down. Frame thread. */
	int fd() const;

private:
	void transmit() override;
	void fetch() override { poll(); }
	void drain();
	void linkLost(int err, const char *operation);
	bool reopen(std::int64_t now_ns);
	SocketCanOpenRequest request() const;

	std::string interface_;
	int bitrate_;
	std::unique_ptr<SocketCanIo> io_;

	/* Frame thread only. */
	std::vector<can_filter> kernel_filters_;
	std::uint32_t kernel_drops_ = 0; /* the socket's drop count last seen */
	std::int64_t next_reopen_ns_ = 0;
	bool never_up_ = false; /* opened Down (the interface was missing or down) and not yet up */
};

/* The pure parts, exposed for tests. None allocates unless it returns a std::string. */
namespace socketcan {

/*
 * Classify one error frame (CAN_ERR_FLAG set; see linux/can/error.h) into
 * stats: error_frames + 1; CAN_ERR_RESTARTED: restarts + 1, ErrorActive;
 * CAN_ERR_CRTL: data[1] passive -> ErrorPassive, else warning ->
 * ErrorWarning, else back-to-active -> ErrorActive (overflow bits alone
 * change nothing); CAN_ERR_BUSOFF: bus_off + 1, BusOff (wins over the rest).
 * A frame without CAN_ERR_FLAG changes nothing.
 */
void classifyErrorFrame(const can_frame &frame, CanStats *stats);

/*
 * CanFrame -> kernel frame: len clamped to 8, EFF flag and 29-bit id when
 * extended. False when the id does not fit (see hal::canFrameProblem).
 */
bool toCanFrame(const CanFrame &frame, can_frame *out);
/* The same for FD: len clamped to 64, rounded up to a CAN FD length, zero padded. */
bool toCanFdFrame(const CanFrame &frame, canfd_frame *out);
/* Kernel frame -> CanFrame; false for error and remote (RTR) frames. Bytes past len are zero. */
bool fromCanFrame(const can_frame &frame, std::int64_t timestamp_ns, CanFrame *out);
bool fromCanFdFrame(const canfd_frame &frame, std::int64_t timestamp_ns, CanFrame *out);

/* CanFilter -> kernel filter: same-kind frames only (EFF flag in the mask), never RTR. */
can_filter toKernelFilter(const CanFilter &filter);

/* What an errno from writing a frame means. */
enum class WriteErrorKind : std::uint8_t {
	QueueFull, /* EAGAIN, EWOULDBLOCK, ENOBUFS: keep the frame, try later */
	Interrupted, /* EINTR: try later, count nothing */
	BadFrame, /* EINVAL, EMSGSIZE, EOVERFLOW: drop this frame */
	LinkLost, /* anything else: the interface is down or gone */
};
WriteErrorKind classifyWriteError(int err);

/* Kernel reception time (CLOCK_REALTIME ns) on CLOCK_MONOTONIC, given both clocks now. */
std::int64_t realtimeToMonotonicNs(std::int64_t rx_realtime_ns, std::int64_t realtime_now_ns,
				   std::int64_t monotonic_now_ns);

/* What open() learns about an interface. */
struct InterfaceInfo {
	int index = 0;
	bool up = false;
	bool is_can = false; /* ARPHRD_CAN */
	int mtu = 0; /* CAN_MTU classic, CANFD_MTU FD-capable */
};
/* Look an interface up with SIOCGIF* ioctls on any socket: 0, or the errno (ENODEV: none such). */
int queryInterface(int fd, const char *name, InterfaceInfo *info);
/* Whether an existing interface can be used; false with the message in error. */
bool checkInterface(const char *name, const InterfaceInfo &info, bool fd, int bitrate,
		    std::span<char> error);

/* "can: this kernel has no SocketCAN support (...)" and the like, for socket()'s errno. */
void socketErrorMessage(int err, std::span<char> error);
/* Interface names are 1 to 15 characters without '/', ':' or whitespace. */
bool validInterfaceName(const std::string &name);
/* Interfaces under sys_class_net (/sys/class/net), in ifindex order; can_only: ARPHRD_CAN ones. */
std::vector<std::string> listInterfaces(const std::string &sys_class_net, bool can_only);
/* "can: no CAN interface "can7" (CAN interfaces present: ...)" from sys_class_net. */
std::string missingInterfaceMessage(const std::string &name, const std::string &sys_class_net);

} /* namespace socketcan */

} /* namespace dockpose::hal */
