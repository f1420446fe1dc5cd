#pragma once
// Binary state in this machine's byte order: what checkpoints are made of. The same calls on a ByteWriter append
// values and on a ByteReader take them back, so a type that saves itself with one function of the form
// `template <class IO> void fields(IO& io, T& value)` can never read back in another order than it wrote.

#include "core/types.h"

#include <cstring>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace ganache {

class ByteWriter {
public:
    template <class T>
    std::enable_if_t<std::is_arithmetic_v<T>> operator()(const T& value) {
        raw(&value, sizeof value);
    }
    void operator()(const Vec3& v) { raw(v.data(), sizeof(Real) * 3); }
    void operator()(const std::string& s) {
        (*this)(std::uint64_t(s.size()));
        bytes += s;
    }
    template <class T>
    void operator()(const std::vector<T>& values) {
        (*this)(std::uint64_t(values.size()));
        if constexpr (std::is_arithmetic_v<T>) raw(values.data(), values.size() * sizeof(T));
        else
            for (const T& v : values) (*this)(v);
    }
    void raw(const void* data, std::size_t size) { bytes.append(static_cast<const char*>(data), size); }

    std::string bytes;
};

/// Reads what a ByteWriter wrote; std::runtime_error when the bytes end early or a length cannot be right.
class ByteReader {
public:
    explicit ByteReader(std::string_view bytes) : m_in(bytes) {}

    template <class T>
    std::enable_if_t<std::is_arithmetic_v<T>> operator()(T& value) {
        raw(&value, sizeof value);
    }
    void operator()(Vec3& v) { raw(v.data(), sizeof(Real) * 3); }
    void operator()(std::string& s) {
        s.resize(count(1));
        raw(s.data(), s.size());
    }
    template <class T>
    void operator()(std::vector<T>& values) {
        values.resize(count(std::is_arithmetic_v<T> ? sizeof(T) : 1));
        if constexpr (std::is_arithmetic_v<T>) raw(values.data(), values.size() * sizeof(T));
        else
            for (T& v : values) (*this)(v);
    }
    void raw(void* data, std::size_t size) {
        if (size > m_in.size() - m_at) throw std::runtime_error("it ends early (truncated)");
        std::memcpy(data, m_in.data() + m_at, size);
        m_at += size;
    }
    /// A length that the rest of the bytes can hold, at `least` bytes per element.
    std::size_t count(std::size_t least) {
        std::uint64_t n = 0;
        (*this)(n);
        if (n > (m_in.size() - m_at) / least) throw std::runtime_error("a length field is larger than the file");
        return std::size_t(n);
    }
    bool atEnd() const { return m_at == m_in.size(); }

private:
    std::string_view m_in;
    std::size_t m_at = 0;
};

}  // namespace ganache
