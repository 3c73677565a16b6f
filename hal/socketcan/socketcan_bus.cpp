/* SPDX-License-Identifier: MIT */
/*
 * SocketCanBus: a raw CAN socket behind CanBusBase's queues (see socketcan_bus.h).
 */
#include "hal/socketcan/socketcan_bus.h"

#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <utility>

#include "hal/clock.h"

/* Older kernel headers. */
#ifndef CAN_ERR_CRTL_ACTIVE
#define CAN_ERR_CRTL_ACTIVE 0x40
#endif
#ifndef CAN_RAW_FILTER_MAX
#define CAN_RAW_FILTER_MAX 512
#endif
#ifndef SO_RXQ_OVFL
#define SO_RXQ_OVFL 40
#endif

namespace dockpose::hal {

namespace {

constexpr can_err_mask_t kErrorMask = CAN_ERR_TX_TIMEOUT | CAN_ERR_CRTL | CAN_ERR_BUSOFF |
				      CAN_ERR_RESTARTED | CAN_ERR_PROT | CAN_ERR_ACK |
				      CAN_ERR_BUSERROR;

/* strerror without allocating (the GNU strerror_r returns a static string or fills buf). */
const char *errorText(int err, char *buf, std::size_t size)
{
	return strerror_r(err, buf, size);
}

void formatInto(std::span<char> out, const char *format, ...) __attribute__((format(printf, 2, 3)));
void formatInto(std::span<char> out, const char *format, ...)
{
	if (out.empty())
		return;
	va_list args;
	va_start(args, format);
	std::vsnprintf(out.data(), out.size(), format, args);
	va_end(args);
}

void copyInto(std::span<char> out, const std::string &text)
{
	if (out.empty())
		return;
	const std::size_t n = std::min(text.size(), out.size() - 1);
	std::memcpy(out.data(), text.data(), n);
	out[n] = '\0';
}

std::int64_t timespecNs(const timespec &ts)
{
	return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

bool isVirtualCanName(const char *name)
{
	return std::strncmp(name, "vcan", 4) == 0 || std::strncmp(name, "vxcan", 5) == 0;
}

/* The real kernel side: one PF_CAN raw socket. */
class KernelSocketCanIo : public SocketCanIo
{
public:
	~KernelSocketCanIo() override { close(); }

	SocketCanOpenResult open(const SocketCanOpenRequest &request, bool describe,
				 std::span<char> error) override;
	void close() override;
	int write(const void *frame, std::size_t size) override;
	int read(SocketCanRead *out) override;
	std::int64_t nowNs() const override { return monotonicNs(); }
	int fd() const override { return fd_; }

private:
	SocketCanOpenResult fail(int s, std::span<char> error, const char *what,
				 const char *interface, int err);

	int fd_ = -1;
};

SocketCanOpenResult KernelSocketCanIo::fail(int s, std::span<char> error, const char *what,
					    const char *interface, int err)
{
	char buf[128];
	formatInto(error, "can: %s on \"%s\" failed: %s", what, interface,
		   errorText(err, buf, sizeof(buf)));
	::close(s);
	return SocketCanOpenResult::Failed;
}

SocketCanOpenResult KernelSocketCanIo::open(const SocketCanOpenRequest &request, bool describe,
					    std::span<char> error)
{
	close();

	const int s = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
	if (s < 0) {
		socketcan::socketErrorMessage(errno, error);
		return SocketCanOpenResult::Failed;
	}

	socketcan::InterfaceInfo info;
	const int err = socketcan::queryInterface(s, request.interface, &info);
	if (err == ENODEV) {
		if (describe)
			copyInto(error, socketcan::missingInterfaceMessage(request.interface,
									   "/sys/class/net"));
		else
			formatInto(error, "can: no CAN interface \"%s\"", request.interface);
		::close(s);
		return SocketCanOpenResult::NotReady;
	}
	if (err)
		return fail(s, error, "looking up the interface", request.interface, err);
	if (!socketcan::checkInterface(request.interface, info, request.fd, request.bitrate,
				       error)) {
		::close(s);
		/* A CAN interface that is down may be brought up; the other problems stay. */
		return info.is_can && !info.up ? SocketCanOpenResult::NotReady
					       : SocketCanOpenResult::Failed;
	}

	/* No filters: an empty list, which receives nothing. */
	const void *filters = request.filters.empty() ? nullptr : request.filters.data();
	const auto filters_size = static_cast<socklen_t>(request.filters.size_bytes());
	if (setsockopt(s, SOL_CAN_RAW, CAN_RAW_FILTER, filters, filters_size) < 0)
		return fail(s, error, "setsockopt(CAN_RAW_FILTER)", request.interface, errno);

	const can_err_mask_t err_mask = kErrorMask;
	if (setsockopt(s, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof(err_mask)) < 0)
		return fail(s, error, "setsockopt(CAN_RAW_ERR_FILTER)", request.interface, errno);

	const int off = 0;
	if (setsockopt(s, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &off, sizeof(off)) < 0)
		return fail(s, error, "setsockopt(CAN_RAW_RECV_OWN_MSGS)", request.interface,
			    errno);

	const int on = 1;
	if (request.fd && setsockopt(s, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof(on)) < 0)
		return fail(s, error, "setsockopt(CAN_RAW_FD_FRAMES)", request.interface, errno);

	/* Both only improve what is reported; without them timestamps are the read time. */
	(void)setsockopt(s, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));
	(void)setsockopt(s, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof(on));

	sockaddr_can addr{};
	addr.can_family = AF_CAN;
	addr.can_ifindex = info.index;
	if (bind(s, reinterpret_cast<const sockaddr *>(&addr), sizeof(addr)) < 0)
		return fail(s, error, "bind", request.interface, errno);

	fd_ = s;
	return SocketCanOpenResult::Opened;
}

void KernelSocketCanIo::close()
{
	if (fd_ >= 0)
		::close(fd_);
	fd_ = -1;
}

int KernelSocketCanIo::write(const void *frame, std::size_t size)
{
	if (fd_ < 0)
		return EBADF;
	const ssize_t n = ::write(fd_, frame, size);
	if (n < 0)
		return errno;
	/* A raw CAN socket takes a frame whole or not at all. */
	return static_cast<std::size_t>(n) == size ? 0 : EMSGSIZE;
}

int KernelSocketCanIo::read(SocketCanRead *out)
{
	if (fd_ < 0)
		return EBADF;

	iovec iov{};
	iov.iov_base = &out->frame;
	iov.iov_len = sizeof(out->frame);
	alignas(cmsghdr) char
		control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t))];
	msghdr msg{};
	msg.msg_iov = &iov;
	msg.msg_iovlen = 1;
	msg.msg_control = control;
	msg.msg_controllen = sizeof(control);

	const ssize_t n = recvmsg(fd_, &msg, MSG_DONTWAIT);
	if (n < 0)
		return errno;

	const std::int64_t monotonic_now_ns = monotonicNs();
	out->size = static_cast<std::size_t>(n);
	out->timestamp_ns = monotonic_now_ns;
	out->has_drop_count = false;
	out->drop_count = 0;

	for (cmsghdr *c = CMSG_FIRSTHDR(&msg); c; c = CMSG_NXTHDR(&msg, c)) {
		if (c->cmsg_level != SOL_SOCKET)
			continue;
		if (c->cmsg_type == SCM_TIMESTAMPNS && c->cmsg_len >= CMSG_LEN(sizeof(timespec))) {
			timespec rx{};
			std::memcpy(&rx, CMSG_DATA(c), sizeof(rx));
			timespec real_now{};
			clock_gettime(CLOCK_REALTIME, &real_now);
			out->timestamp_ns = socketcan::realtimeToMonotonicNs(
				timespecNs(rx), timespecNs(real_now), monotonic_now_ns);
		} else if (c->cmsg_type == SO_RXQ_OVFL &&
			   c->cmsg_len >= CMSG_LEN(sizeof(std::uint32_t))) {
			std::memcpy(&out->drop_count, CMSG_DATA(c), sizeof(out->drop_count));
			out->has_drop_count = true;
		}
	}
	return 0;
}

} /* namespace */

std::unique_ptr<SocketCanIo> makeKernelSocketCanIo()
{
	return std::make_unique<KernelSocketCanIo>();
}

/* ------------------------------------------------------------------------- */

SocketCanBus::SocketCanBus(std::string interface, int bitrate)
	: SocketCanBus(std::move(interface), makeKernelSocketCanIo(), bitrate)
{
}

SocketCanBus::SocketCanBus(std::string interface, std::unique_ptr<SocketCanIo> io, int bitrate)
	: CanBusBase("socketcan:" + interface),
	  interface_(std::move(interface)),
	  bitrate_(bitrate),
	  io_(std::move(io))
{
}

SocketCanBus::~SocketCanBus()
{
	close();
}

SocketCanOpenRequest SocketCanBus::request() const
{
	SocketCanOpenRequest r;
	r.interface = interface_.c_str();
	r.filters = kernel_filters_;
	r.fd = fdEnabled();
	r.bitrate = bitrate_;
	return r;
}

Status SocketCanBus::open(std::span<const CanFilter> filters, const CanOptions &options)
{
	close();
	kernel_drops_ = 0;
	never_up_ = false;
	if (Status s = openQueues(options, kRxRingFrames); !s.isOk())
		return s;

	bool valid = true;
	if (!socketcan::validInterfaceName(interface_)) {
		setError("can: \"%s\" is not a valid interface name "
			 "(1 to %d characters, no '/', ':' or spaces)",
			 interface_.c_str(), IFNAMSIZ - 1);
		valid = false;
	} else if (filters.size() > CAN_RAW_FILTER_MAX) {
		setError("can: %zu filters, the kernel takes at most %d", filters.size(),
			 CAN_RAW_FILTER_MAX);
		valid = false;
	}
	if (!valid) {
		publish();
		return Status::error(lastError());
	}

	kernel_filters_.clear();
	kernel_filters_.reserve(filters.size());
	for (const CanFilter &f : filters)
		kernel_filters_.push_back(socketcan::toKernelFilter(f));

	switch (io_->open(request(), true, errorBuffer())) {
	case SocketCanOpenResult::Opened:
		markOpen();
		return Status::ok();
	case SocketCanOpenResult::NotReady: {
		/* Open, but Down until the interface is there and up: poll() reopens it. */
		const std::string why = lastError();
		markOpen();
		stats_.state = CanState::Down;
		never_up_ = true;
		next_reopen_ns_ =
			io_->nowNs() + static_cast<std::int64_t>(kReopenInterval_ms) * 1000000;
		setError("%s; waiting for it (retried every %d ms)", why.c_str(),
			 kReopenInterval_ms);
		publish();
		return Status::ok();
	}
	case SocketCanOpenResult::Failed:
		break;
	}
	publish();
	return Status::error(lastError());
}

void SocketCanBus::close()
{
	io_->close();
	closeQueues();
}

void SocketCanBus::poll()
{
	if (!isOpen())
		return;
	if (stats_.state == CanState::Down) {
		const std::int64_t now_ns = io_->nowNs();
		expire(monotonicNs());
		if (now_ns < next_reopen_ns_) {
			publish();
			return;
		}
		if (!reopen(now_ns)) {
			publish();
			return;
		}
	}
	transmit();
	drain();
	publish();
}

int SocketCanBus::fd() const
{
	return isOpen() ? io_->fd() : -1;
}

void SocketCanBus::transmit()
{
	/* Deadlines are CLOCK_MONOTONIC, as send() stamps them (io_'s clock paces reopening). */
	const std::int64_t now_ns = monotonicNs();
	if (stats_.state == CanState::Down) {
		expire(now_ns);
		return;
	}
	while (const CanFrame *next = nextToSend(now_ns)) {
		const CanFrame &frame = *next;
		int err;
		if (frame.fd) {
			canfd_frame k;
			socketcan::toCanFdFrame(frame, &k);
			err = io_->write(&k, CANFD_MTU);
		} else {
			can_frame k;
			socketcan::toCanFrame(frame, &k);
			err = io_->write(&k, CAN_MTU);
		}
		if (err == 0) {
			tx_.pop();
			++stats_.tx_frames;
			continue;
		}

		char buf[128];
		switch (socketcan::classifyWriteError(err)) {
		case socketcan::WriteErrorKind::QueueFull:
			++stats_.tx_enobufs;
			return;
		case socketcan::WriteErrorKind::Interrupted:
			return;
		case socketcan::WriteErrorKind::BadFrame:
			++stats_.tx_errors;
			setError("can: %s refused frame 0x%x (%s); dropped", interface_.c_str(),
				 frame.id, errorText(err, buf, sizeof(buf)));
			tx_.pop();
			continue;
		case socketcan::WriteErrorKind::LinkLost:
			++stats_.tx_errors;
			linkLost(err, "write");
			return;
		}
	}
}

void SocketCanBus::drain()
{
	for (int i = 0; i < kMaxReadsPerPoll && stats_.state != CanState::Down; ++i) {
		SocketCanRead r;
		const int err = io_->read(&r);
		if (err == EAGAIN || err == EWOULDBLOCK)
			return;
		if (err == EINTR)
			continue;
		if (err) {
			linkLost(err, "read");
			return;
		}

		if (r.has_drop_count) {
			/* A running count; unsigned arithmetic survives its wrap. */
			countRxLost(static_cast<std::uint32_t>(r.drop_count - kernel_drops_));
			kernel_drops_ = r.drop_count;
		}

		CanFrame frame;
		if (r.size == CAN_MTU) {
			can_frame k;
			std::memcpy(&k, &r.frame, CAN_MTU);
			if (k.can_id & CAN_ERR_FLAG) {
				socketcan::classifyErrorFrame(k, &stats_);
				continue;
			}
			if (socketcan::fromCanFrame(k, r.timestamp_ns, &frame))
				received(frame);
		} else if (r.size == CANFD_MTU) {
			if (socketcan::fromCanFdFrame(r.frame, r.timestamp_ns, &frame))
				received(frame);
		} else {
			setError("can: %s gave a frame of %zu bytes (neither %zu nor %zu); ignored",
				 interface_.c_str(), r.size, CAN_MTU, CANFD_MTU);
		}
	}
}

void SocketCanBus::linkLost(int err, const char *operation)
{
	io_->close();
	stats_.state = CanState::Down;
	/* The first attempt at the next poll(): a quick bounce costs one poll. */
	next_reopen_ns_ = io_->nowNs();
	char buf[128];
	setError("can: lost %s (%s: %s); queueing, reopening every %d ms", interface_.c_str(),
		 operation, errorText(err, buf, sizeof(buf)), kReopenInterval_ms);
}

bool SocketCanBus::reopen(std::int64_t now_ns)
{
	if (io_->open(request(), false, errorBuffer()) != SocketCanOpenResult::Opened) {
		next_reopen_ns_ = now_ns + static_cast<std::int64_t>(kReopenInterval_ms) * 1000000;
		return false;
	}
	kernel_drops_ = 0;
	/* Joining late, the first time, is no restart. */
	if (!never_up_)
		++stats_.restarts;
	never_up_ = false;
	stats_.state = CanState::ErrorActive;
	return true;
}

/* ------------------------------------------------------------------------- */

namespace socketcan {

void classifyErrorFrame(const can_frame &frame, CanStats *stats)
{
	if (!(frame.can_id & CAN_ERR_FLAG))
		return;
	const canid_t classes = frame.can_id & CAN_ERR_MASK;
	++stats->error_frames;

	if (classes & CAN_ERR_RESTARTED) {
		++stats->restarts;
		stats->state = CanState::ErrorActive;
	}
	if (classes & CAN_ERR_CRTL) {
		const std::uint8_t status = frame.data[1];
		if (status & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE))
			stats->state = CanState::ErrorPassive;
		else if (status & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING))
			stats->state = CanState::ErrorWarning;
		else if (status & CAN_ERR_CRTL_ACTIVE)
			stats->state = CanState::ErrorActive;
	}
	if (classes & CAN_ERR_BUSOFF) {
		++stats->bus_off;
		stats->state = CanState::BusOff;
	}
}

namespace {

canid_t kernelId(const CanFrame &frame)
{
	return frame.extended ? (frame.id & CAN_EFF_MASK) | CAN_EFF_FLAG : frame.id & CAN_SFF_MASK;
}

} /* namespace */

bool toCanFrame(const CanFrame &frame, can_frame *out)
{
	*out = can_frame{};
	if (frame.extended ? frame.id > CAN_EFF_MASK : frame.id > CAN_SFF_MASK)
		return false;
	out->can_id = kernelId(frame);
	const std::uint8_t len = std::min<std::uint8_t>(frame.len, CAN_MAX_DLEN);
	out->can_dlc = len;
	std::memcpy(out->data, frame.data.data(), len);
	return true;
}

bool toCanFdFrame(const CanFrame &frame, canfd_frame *out)
{
	*out = canfd_frame{};
	if (frame.extended ? frame.id > CAN_EFF_MASK : frame.id > CAN_SFF_MASK)
		return false;
	out->can_id = kernelId(frame);
	const std::uint8_t len = std::min<std::uint8_t>(frame.len, CANFD_MAX_DLEN);
	out->len = canFdLength(len);
	std::memcpy(out->data, frame.data.data(), len); /* the padding stays zero */
	return true;
}

bool fromCanFrame(const can_frame &frame, std::int64_t timestamp_ns, CanFrame *out)
{
	if (frame.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG))
		return false;
	*out = CanFrame{};
	out->extended = (frame.can_id & CAN_EFF_FLAG) != 0;
	out->id = frame.can_id & (out->extended ? CAN_EFF_MASK : CAN_SFF_MASK);
	out->fd = false;
	out->len = std::min<std::uint8_t>(frame.can_dlc, CAN_MAX_DLEN);
	std::memcpy(out->data.data(), frame.data, out->len);
	out->timestamp_ns = timestamp_ns;
	return true;
}

bool fromCanFdFrame(const canfd_frame &frame, std::int64_t timestamp_ns, CanFrame *out)
{
	if (frame.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG))
		return false;
	*out = CanFrame{};
	out->extended = (frame.can_id & CAN_EFF_FLAG) != 0;
	out->id = frame.can_id & (out->extended ? CAN_EFF_MASK : CAN_SFF_MASK);
	out->fd = true;
	out->len = std::min<std::uint8_t>(frame.len, CANFD_MAX_DLEN);
	std::memcpy(out->data.data(), frame.data, out->len);
	out->timestamp_ns = timestamp_ns;
	return true;
}

can_filter toKernelFilter(const CanFilter &filter)
{
	can_filter k{};
	if (filter.extended) {
		k.can_id = (filter.id & CAN_EFF_MASK) | CAN_EFF_FLAG;
		k.can_mask = (filter.mask & CAN_EFF_MASK) | CAN_EFF_FLAG | CAN_RTR_FLAG;
	} else {
		k.can_id = filter.id & CAN_SFF_MASK;
		k.can_mask = (filter.mask & CAN_SFF_MASK) | CAN_EFF_FLAG | CAN_RTR_FLAG;
	}
	return k;
}

WriteErrorKind classifyWriteError(int err)
{
	switch (err) {
	case EAGAIN:
#if EWOULDBLOCK != EAGAIN
	case EWOULDBLOCK:
#endif
	case ENOBUFS:
		return WriteErrorKind::QueueFull;
	case EINTR:
		return WriteErrorKind::Interrupted;
	case EINVAL:
	case EMSGSIZE:
	case EOVERFLOW:
		return WriteErrorKind::BadFrame;
	default:
		return WriteErrorKind::LinkLost;
	}
}

std::int64_t realtimeToMonotonicNs(std::int64_t rx_realtime_ns, std::int64_t realtime_now_ns,
				   std::int64_t monotonic_now_ns)
{
	if (rx_realtime_ns <= 0)
		return monotonic_now_ns;
	const std::int64_t age_ns = realtime_now_ns - rx_realtime_ns;
	/* The wall clock stepped back since the reception: the read time is the best we have. */
	if (age_ns < 0)
		return monotonic_now_ns;
	return monotonic_now_ns - age_ns;
}

int queryInterface(int fd, const char *name, InterfaceInfo *info)
{
	*info = InterfaceInfo{};
	if (std::strlen(name) == 0 || std::strlen(name) >= IFNAMSIZ)
		return ENODEV;

	ifreq ifr{};
	std::memcpy(ifr.ifr_name, name, std::strlen(name));
	if (ioctl(fd, SIOCGIFINDEX, &ifr) < 0)
		return errno;
	info->index = ifr.ifr_ifindex;
	if (ioctl(fd, SIOCGIFFLAGS, &ifr) < 0)
		return errno;
	info->up = (ifr.ifr_flags & IFF_UP) != 0;
	if (ioctl(fd, SIOCGIFHWADDR, &ifr) < 0)
		return errno;
	info->is_can = ifr.ifr_hwaddr.sa_family == ARPHRD_CAN;
	if (ioctl(fd, SIOCGIFMTU, &ifr) < 0)
		return errno;
	info->mtu = ifr.ifr_mtu;
	return 0;
}

bool checkInterface(const char *name, const InterfaceInfo &info, bool fd, int bitrate,
		    std::span<char> error)
{
	if (!info.is_can) {
		formatInto(error, "can: interface \"%s\" is not a CAN interface", name);
		return false;
	}
	if (!info.up) {
		if (isVirtualCanName(name))
			formatInto(error, "can: interface \"%s\" is down (ip link set %s up)", name,
				   name);
		else if (bitrate > 0)
			formatInto(error,
				   "can: interface \"%s\" is down "
				   "(ip link set %s up type can bitrate %d)",
				   name, name, bitrate);
		else
			formatInto(error,
				   "can: interface \"%s\" is down "
				   "(ip link set %s up type can bitrate <bit/s>)",
				   name, name);
		return false;
	}
	if (fd && info.mtu < static_cast<int>(CANFD_MTU)) {
		formatInto(error,
			   "can: interface \"%s\" does not support CAN FD (MTU %d, not %zu: "
			   "ip link set %s type can ... fd on)",
			   name, info.mtu, CANFD_MTU, name);
		return false;
	}
	return true;
}

void socketErrorMessage(int err, std::span<char> error)
{
	char buf[128];
	const char *text = errorText(err, buf, sizeof(buf));
	if (err == EAFNOSUPPORT)
		formatInto(error, "can: this kernel has no SocketCAN support (socket(PF_CAN): %s)",
			   text);
	else if (err == EPROTONOSUPPORT)
		formatInto(error,
			   "can: this kernel has SocketCAN but no raw CAN sockets, "
			   "CONFIG_CAN_RAW (socket(PF_CAN, CAN_RAW): %s)",
			   text);
	else
		formatInto(error, "can: socket(PF_CAN) failed: %s", text);
}

bool validInterfaceName(const std::string &name)
{
	if (name.empty() || name.size() >= IFNAMSIZ || name == "." || name == "..")
		return false;
	for (char c : name)
		if (c == '/' || c == ':' || std::isspace(static_cast<unsigned char>(c)))
			return false;
	return true;
}

std::vector<std::string> listInterfaces(const std::string &sys_class_net, bool can_only)
{
	namespace fs = std::filesystem;
	std::vector<std::pair<long, std::string>> found;
	std::error_code ec;
	fs::directory_iterator it(sys_class_net, ec);
	for (const fs::directory_iterator end{}; !ec && it != end; it.increment(ec)) {
		const std::string name = it->path().filename().string();
		long type = -1;
		long index = 0;
		std::ifstream type_file(it->path() / "type");
		if (!(type_file >> type))
			continue; /* not an interface (bonding_masters, ...) */
		std::ifstream index_file(it->path() / "ifindex");
		index_file >> index;
		if (can_only && type != ARPHRD_CAN)
			continue;
		found.emplace_back(index, name);
	}
	std::sort(found.begin(), found.end());
	std::vector<std::string> names;
	names.reserve(found.size());
	for (auto &f : found)
		names.push_back(std::move(f.second));
	return names;
}

std::string missingInterfaceMessage(const std::string &name, const std::string &sys_class_net)
{
	const auto join = [](const std::vector<std::string> &names) {
		std::string s;
		for (const std::string &n : names)
			s += (s.empty() ? "" : ", ") + n;
		return s;
	};
	std::string message = "can: no CAN interface \"" + name + "\"";
	const std::vector<std::string> can = listInterfaces(sys_class_net, true);
	if (!can.empty())
		return message + " (CAN interfaces present: " + join(can) + ")";
	const std::vector<std::string> all = listInterfaces(sys_class_net, false);
	if (!all.empty())
		return message + " (interfaces present: " + join(all) +
		       "; none is a CAN interface)";
	return message;
}

} /* namespace socketcan */

} /* namespace dockpose::hal */
