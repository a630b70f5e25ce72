// Live preview (--display-server HOST:PORT, RIB Display "framebuffer"): the render's buckets streamed to a
// tev viewer as they finish (io/display_client.h). The viewer holds the whole display window, linear
// premultiplied RGBA as the EXR stores it, with the Imager background composited as render() does.
#pragma once
#include <fmt/core.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "film/film.h"
#include "io/display_client.h"

namespace tessera::cli {

// tev's default port (tev --hostname 127.0.0.1:14158).
inline constexpr const char* kDefaultDisplayServer = "127.0.0.1:14158";

class LivePreview {
  public:
    // Connects; a server that does not answer is a warning (printed unless quiet) and the render goes on.
    LivePreview(const std::string& address, std::string imageName, int width, int height,
                std::optional<Color> background, bool quiet)
        : address_(address),
          name_(std::move(imageName)),
          background_(background),
          quiet_(quiet),
          client_(std::make_unique<DisplayClient>(address)) {
        if (!client_->connected()) {
            warn(client_->error());
            return;
        }
        client_->send(tev::createImagePacket(name_, width, height, channels()));
    }
    ~LivePreview() { finish(); }

    // The pixels `r` of `image` (final), averaged with `previous` passes whose sum is `sum` (passes > 1).
    // Called from worker threads: reads only those pixels.
    void update(const Image& image, const Rect& r, const Image* sum = nullptr, int previous = 0) {
        if (!client_ || !client_->connected() || r.width() <= 0 || r.height() <= 0) return;
        std::vector<float> px(size_t(r.width()) * r.height() * 4);
        const float k = 1.f / float(previous + 1);
        size_t i = 0;
        for (int y = r.y0; y < r.y1; ++y)
            for (int x = r.x0; x < r.x1; ++x, i += 4) {
                const float* p = image.pixel(x, y);
                const float* s = sum && previous > 0 ? sum->pixel(x, y) : nullptr;
                for (int c = 0; c < 4; ++c) px[i + c] = s ? (s[c] + p[c]) * k : p[c];
                if (background_) {  // render()'s Imager "background", on the bucket's pixels
                    const float open = 1.f - px[i + 3];
                    px[i] += open * background_->x, px[i + 1] += open * background_->y;
                    px[i + 2] += open * background_->z, px[i + 3] = 1.f;
                }
            }
        client_->send(
            tev::updateImagePacket(name_, channels(), r.x0, r.y0, r.width(), r.height(), px.data()));
    }
    // Sends what is queued; a connection lost on the way is a warning.
    void finish() {
        if (!client_) return;
        const bool wasConnected = client_->connected();
        client_->flush();
        if (wasConnected && !client_->connected()) warn(client_->error());
        client_.reset();
    }

  private:
    static const std::vector<std::string>& channels() {
        static const std::vector<std::string> names{"R", "G", "B", "A"};
        return names;
    }
    void warn(const std::string& why) const {
        if (!quiet_)
            fmt::print(stderr,
                       "warning: display server {}: {}; the render goes on without the live preview\n",
                       address_, why);
    }
    std::string address_, name_;
    std::optional<Color> background_;
    bool quiet_;
    std::unique_ptr<DisplayClient> client_;
};

}  // namespace tessera::cli
