// Live preview: a client of the tev image viewer's network protocol (github.com/Tom94/tev, src/Ipc.cpp;
// the protocol pbrt-v4's --display-server speaks). Every packet is a little-endian uint32 holding the
// packet's whole length (these four bytes included), a type byte, then its fields: strings end in a NUL,
// bool is one byte. We send CreateImage (type 4) once and UpdateImageV3 (type 6) per finished bucket.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace tessera {

namespace tev {
enum PacketType : uint8_t { kCloseImage = 2, kCreateImage = 4, kUpdateImageV3 = 6 };
// CreateImage: grabFocus, name, int32 width, height, channel count, channel names.
std::vector<char> createImagePacket(const std::string& name, int width, int height,
                                    const std::vector<std::string>& channels, bool grabFocus = true);
// UpdateImageV3: grabFocus, name, int32 channel count, channel names, int32 x, y, width, height, int64
// offset and stride per channel (in floats), then the floats. `pixels` is width * height pixels of
// channels.size() interleaved floats, row-major (channel c of pixel i at i * n + c).
std::vector<char> updateImagePacket(const std::string& name, const std::vector<std::string>& channels, int x,
                                    int y, int width, int height, const float* pixels,
                                    bool grabFocus = false);
std::vector<char> closeImagePacket(const std::string& name);
}  // namespace tev

// A connection to a display server, with its sends on a thread of their own so a slow viewer never stalls
// the render: send() queues a packet and returns. A server that is not there or goes away is reported by
// error() (the caller warns) and later packets are dropped; nothing throws.
class DisplayClient {
  public:
    // "HOST:PORT" (HOST a name or IPv4/IPv6 address, "[v6]:PORT" too). Connects with a timeout of
    // `timeoutMs`; on failure connected() is false and error() says why.
    explicit DisplayClient(const std::string& address, int timeoutMs = 2000);
    ~DisplayClient();  // sends what is queued (each send bounded by a timeout), then closes
    DisplayClient(const DisplayClient&) = delete;
    DisplayClient& operator=(const DisplayClient&) = delete;

    bool connected() const;
    void send(std::vector<char> packet);
    // Blocks until every queued packet is sent or dropped.
    void flush();
    // The first failure ("" if none): connection refused, host unknown, send failed.
    std::string error() const;

    // Splits "HOST:PORT"; false on a malformed address (no port, port not 1..65535).
    static bool parseAddress(std::string_view address, std::string& host, int& port);

  private:
    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace tessera
