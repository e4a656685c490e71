// bcryptprimitives.dll for Wine 8 (Debian 12's wine64), which lacks it. Rust's standard library
// on Windows 10+ draws random bytes (HashMap seeds) from its ProcessPrng, so a test executable
// does not start without it. Windows 10 and 11 ship the real DLL; this one exists only for the
// Wine run of the core's tests (make test-windows) and forwards to bcrypt.dll, which Wine has.
#include <windows.h>
#include <bcrypt.h>

__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T size) {
    while (size > 0) {
        ULONG part = size > 0x40000000 ? 0x40000000 : (ULONG)size;
        if (BCryptGenRandom(NULL, data, part, BCRYPT_USE_SYSTEM_PREFERRED_RNG) != 0) {
            return FALSE;
        }
        data += part;
        size -= part;
    }
    return TRUE;
}
