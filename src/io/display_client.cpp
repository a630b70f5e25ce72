#include "io/display_client.h"

#include <fcntl.h>
#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cerrno>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>
#include <thread>

namespace tessera {

namespace tev {
namespace {

// Little-endian fields, as tev reads them (it copies the bytes into host integers; x86 and ARM hosts).
struct PacketWriter {
    std::vector<char> bytes;
    PacketWriter() { put(uint32_t(0)); }  // the length, patched by finish()
    template <class T>
    void put(T v) {
        char raw[sizeof(T)];
        std::memcpy(raw, &v, sizeof(T));
        bytes.insert(bytes.end(), raw, raw + sizeof(T));
    }
    void putString(const std::string& s) {
        bytes.insert(bytes.end(), s.begin(), s.end());
        bytes.push_back('\0');
    }
    void putBool(bool b) { bytes.push_back(b ? 1 : 0); }
    std::vector<char> finish() {
        const uint32_t n = uint32_t(bytes.size());
        std::memcpy(bytes.data(), &n, sizeof n);
        return std::move(bytes);
    }
};

}  // namespace

std::vector<char> createImagePacket(const std::string& name, int width, int height,
                                    const std::vector<std::string>& channels, bool grabFocus) {
    PacketWriter w;
    w.put(uint8_t(kCreateImage));
    w.putBool(grabFocus);
    w.putString(name);
    w.put(int32_t(width));
    w.put(int32_t(height));
    w.put(int32_t(channels.size()));
    for (const std::string& c : channels) w.putString(c);
    return w.finish();
}

std::vector<char> updateImagePacket(const std::string& name, const std::vector<std::string>& channels, int x,
                                    int y, int width, int height, const float* pixels, bool grabFocus) {
    PacketWriter w;
    const int64_t n = int64_t(channels.size());
    w.put(uint8_t(kUpdateImageV3));
    w.putBool(grabFocus);
    w.putString(name);
    w.put(int32_t(n));
    for (const std::string& c : channels) w.putString(c);
    w.put(int32_t(x));
    w.put(int32_t(y));
    w.put(int32_t(width));
    w.put(int32_t(height));
    for (int64_t c = 0; c < n; ++c) w.put(c);  // offsets: interleaved channels
    for (int64_t c = 0; c < n; ++c) w.put(n);  // strides
    const size_t floats = size_t(width) * size_t(height) * size_t(n);
    const char* raw = reinterpret_cast<const char*>(pixels);
    w.bytes.insert(w.bytes.end(), raw, raw + floats * sizeof(float));
    return w.finish();
}

std::vector<char> closeImagePacket(const std::string& name) {
    PacketWriter w;
    w.put(uint8_t(kCloseImage));
    w.putString(name);
    return w.finish();
}

}  // namespace tev

namespace {

// Connects to host:port within timeoutMs (non-blocking connect, then poll); -1 and `error` on failure.
int connectWithTimeout(const std::string& host, int port, int timeoutMs, std::string& error) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* found = nullptr;
    const std::string service = std::to_string(port);
    if (int rc = getaddrinfo(host.c_str(), service.c_str(), &hints, &found); rc != 0) {
        error = "cannot resolve '" + host + "': " + gai_strerror(rc);
        return -1;
    }
    int fd = -1;
    for (addrinfo* a = found; a && fd < 0; a = a->ai_next) {
        fd = socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
        if (fd < 0) {
            error = std::string("socket: ") + std::strerror(errno);
            continue;
        }
        const int flags = fcntl(fd, F_GETFL, 0);
        fcntl(fd, F_SETFL, flags | O_NONBLOCK);
        int rc = connect(fd, a->ai_addr, a->ai_addrlen);
        if (rc < 0 && errno == EINPROGRESS) {
            pollfd p{fd, POLLOUT, 0};
            rc = poll(&p, 1, timeoutMs);
            if (rc == 0) {
                errno = ETIMEDOUT;
                rc = -1;
            } else if (rc > 0) {
                int soError = 0;
                socklen_t len = sizeof soError;
                getsockopt(fd, SOL_SOCKET, SO_ERROR, &soError, &len);
                errno = soError;
                rc = soError ? -1 : 0;
            }
        }
        if (rc < 0) {
            error = "cannot connect to " + host + ":" + service + ": " + std::strerror(errno);
            close(fd);
            fd = -1;
            continue;
        }
        fcntl(fd, F_SETFL, flags);  // blocking sends, each bounded by SO_SNDTIMEO
        timeval tv{5, 0};
        setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    }
    freeaddrinfo(found);
    return fd;
}

bool sendAll(int fd, const std::vector<char>& bytes) {
    size_t sent = 0;
    while (sent < bytes.size()) {
        const ssize_t n = ::send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return false;
        sent += size_t(n);
    }
    return true;
}

// Queued bytes beyond which send() waits for the sender (a viewer slower than the render): bounded memory.
constexpr size_t kMaxQueuedBytes = size_t(256) << 20;

}  // namespace

struct DisplayClient::State {
    int fd = -1;
    std::mutex mutex;
    std::condition_variable changed;
    std::deque<std::vector<char>> queue;
    size_t queuedBytes = 0;
    bool sending = false;  // the sender holds a packet it took off the queue
    bool stopping = false;
    std::string error;
    std::thread sender;

    void run() {
        std::unique_lock lock(mutex);
        for (;;) {
            changed.wait(lock, [&] { return stopping || !queue.empty(); });
            if (queue.empty()) return;  // stopping, all sent
            std::vector<char> packet = std::move(queue.front());
            queue.pop_front();
            queuedBytes -= packet.size();
            sending = true;
            const bool ok = fd >= 0 && error.empty();
            lock.unlock();
            const bool sent = ok && sendAll(fd, packet);
            lock.lock();
            sending = false;
            if (ok && !sent)
                error = std::string("the display server stopped taking packets: ") + std::strerror(errno);
            changed.notify_all();
        }
    }
};

bool DisplayClient::parseAddress(std::string_view address, std::string& host, int& port) {
    const size_t colon = address.rfind(':');
    if (colon == std::string_view::npos || colon == 0 || colon + 1 == address.size()) return false;
    std::string_view h = address.substr(0, colon), p = address.substr(colon + 1);
    if (h.front() == '[' && h.back() == ']') h = h.substr(1, h.size() - 2);
    if (h.empty() || p.size() > 5) return false;
    int value = 0;
    for (char c : p) {
        if (c < '0' || c > '9') return false;
        value = value * 10 + (c - '0');
    }
    if (value < 1 || value > 65535) return false;
    host = std::string(h);
    port = value;
    return true;
}

DisplayClient::DisplayClient(const std::string& address, int timeoutMs) : state_(std::make_unique<State>()) {
    std::string host;
    int port = 0;
    if (!parseAddress(address, host, port)) {
        state_->error = "'" + address + "' is not HOST:PORT";
        return;
    }
    state_->fd = connectWithTimeout(host, port, timeoutMs, state_->error);
    if (state_->fd >= 0) state_->sender = std::thread([s = state_.get()] { s->run(); });
}

DisplayClient::~DisplayClient() {
    if (state_->sender.joinable()) {
        {
            std::lock_guard lock(state_->mutex);
            state_->stopping = true;
        }
        state_->changed.notify_all();
        state_->sender.join();
    }
    if (state_->fd >= 0) close(state_->fd);
}

bool DisplayClient::connected() const {
    std::lock_guard lock(state_->mutex);
    return state_->fd >= 0 && state_->error.empty();
}

void DisplayClient::send(std::vector<char> packet) {
    std::unique_lock lock(state_->mutex);
    if (state_->fd < 0 || !state_->error.empty()) return;
    state_->changed.wait(lock,
                         [&] { return state_->queuedBytes < kMaxQueuedBytes || !state_->error.empty(); });
    if (!state_->error.empty()) return;
    state_->queuedBytes += packet.size();
    state_->queue.push_back(std::move(packet));
    state_->changed.notify_all();
}

void DisplayClient::flush() {
    std::unique_lock lock(state_->mutex);
    if (state_->fd < 0) return;
    state_->changed.wait(lock, [&] { return state_->queue.empty() && !state_->sending; });
}

std::string DisplayClient::error() const {
    std::lock_guard lock(state_->mutex);
    return state_->error;
}

}  // namespace tessera
